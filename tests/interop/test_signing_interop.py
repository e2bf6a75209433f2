"""MAVLink2 signing with real clients: MAVProxy sets the key up, MAVProxy with the key flies, a
client without it gets nothing accepted, MAVSDK (no signing support) works only on a trusted link.

gcsd runs with `signing: {require: true}` and two UDP server channels: `gcs` (plain: unsigned
packets refused) and `trusted` (options [unsigned_ok]). The clients are run as their users run them:

- MAVProxy on `trusted`: `signing setup PASSPHRASE` sends SETUP_SIGNING (key = SHA-256 of the
  passphrase, REFERENCE.md section 9, CLIENTS.md) and starts signing its own link with that key;
  gcsd answers with the STATUSTEXT "Signing enabled", signed with the new key. It runs as
  sysid 253: MAVLink signing streams are keyed by (sysid, compid, link id) across all links, and
  two MAVProxy processes both use link id 0, so two of them as sysid 255 would be one stream
  with two interleaved clocks (the later one's timestamps make the other's look like replays).
- MAVProxy on `gcs` with `signing key PASSPHRASE` (the key, without sending it): `param set` is
  confirmed by the value read back and `arm throttle` by COMMAND_ACK ACCEPTED and the
  HEARTBEAT's armed flag.
- A pymavlink ground station without the key on `gcs`: its arm, PARAM_SET and PARAM_REQUEST_READ
  get no answer, it sees the STATUSTEXT explaining the rejection, and `gcsd status --json`
  counts its packets as `signature_reject_reasons.unsigned` on `gcs` (none on `trusted`).
- MAVProxy's `signing setup` while the vehicle is armed is refused with a STATUSTEXT that reaches
  it, and the key in use does not change.
- MAVSDK (the `mavsdk` package; no signing support): on `gcs` it still discovers the autopilot
  (gcsd's signed output is readable without the key) but its arm gets no COMMAND_ACK and fails with
  a timeout; on `trusted` it arms.
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import os
import re
import subprocess
import sys
import time
from contextlib import aclosing
from pathlib import Path

import pytest

pytest.importorskip("MAVProxy", reason="MAVProxy is a test extra: pip install -e .[test]")
pytest.importorskip("mavsdk.asyncio", reason="mavsdk is a test extra: pip install -e .[test]")

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync, ActionError
from mavsdk.asyncio.plugins.telemetry import FixType, TelemetryAsync
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as M

from .conftest import REPO_ROOT
from .conftest import expect_line as _expect
from .conftest import mavproxy_script as _mavproxy_script

pytestmark = pytest.mark.interop

PASSPHRASE = "gcsd-interop-sesame"
KEY = hashlib.sha256(PASSPHRASE.encode("ascii")).digest()  # what MAVProxy derives from it
VEHICLE = (1, 1)
KEYLESS_SYSID, KEYLESS_COMPID = 250, 190
TRUSTED_MAVPROXY_SYSID = 253
MAV_MODE_FLAG_SAFETY_ARMED = 128
PARAM = "SR1_EXTRA1"
KEYLESS_VALUE = 7  # what the client without the key tries to set

DETECT_WAIT_S = 10.0  # MAVProxy's start-up (imports) included
TEXT_WAIT_S = 3.0
ACK_WAIT_S = 3.0
HEARTBEAT_STATE_WAIT_S = 3.0
SET_WAIT_S = 3.0  # MAVProxy retries a set once a second, 3 attempts
NO_ANSWER_WAIT_S = 3.0  # how long a refused client waits in vain
DISCOVERY_WAIT_S = 5.0
TELEMETRY_WAIT_S = 3.0

HEARTBEAT_LINE = re.compile(r"HEARTBEAT \{type : \d+, autopilot : \d+, base_mode : (?P<base_mode>\d+)")


def _channels() -> list[dict]:
    return [
        {"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"},
        {"name": "trusted", "type": "udp-server", "address": "127.0.0.1:0", "options": ["unsigned_ok"]},
    ]


def _status(daemon) -> dict[str, dict]:
    """`python -m gcsd status -c CFG --json`, as an operator runs it: channels by name."""
    pythonpath = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    pythonpath.append(str(REPO_ROOT / "src"))
    out = subprocess.run(
        [sys.executable, "-m", "gcsd", "status", "-c", str(daemon.config_path), "--json"],
        check=False, capture_output=True, text=True, timeout=30,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(pythonpath)},
    )
    assert out.returncode == 0, f"gcsd status failed: {out.stderr}\n{daemon.describe()}"
    return {ch["name"]: ch for ch in json.loads(out.stdout)["channels"]}


# ---------------------------------------------------------------------------------------------
# MAVProxy


def _start_mavproxy(spawn, tmp_path: Path, port: int, name: str, *extra: str):
    """Headless MAVProxy with the modules this test uses; HOME=tmp_path so no key file of the
    user's (~/.mavproxy/signing.keys) is read."""
    return spawn(
        [
            sys.executable,
            _mavproxy_script(),
            f"--master=udpout:127.0.0.1:{port}",
            "--no-state",
            "--default-modules=signing,param,arm,mode",
            "--cmd=set param_ftp 0",
            *extra,
        ],
        name=name,
        cwd=tmp_path,
        env_overrides={"HOME": str(tmp_path)},
    )


def _fetched_value(process, daemon, name: str, accept, timeout_s: float) -> float:
    """`param fetch NAME` (a PARAM_REQUEST_READ; MAVProxy prints `NAME = VALUE` when the answer
    comes) until the value is accepted."""
    line = re.compile(rf"(?:^|> ){re.escape(name)} = (?P<value>\S+)$")
    deadline = time.monotonic() + timeout_s
    fetched = []
    while time.monotonic() < deadline:
        since = len(process.output)
        process.send_line(f"param fetch {name}")
        found = process.output.wait_for(line, 1.0, since=since)
        if found is not None:
            value = float(found[2]["value"])
            if accept(value):
                return value
            fetched.append(value)
            time.sleep(0.2)
    pytest.fail(
        f"`param fetch {name}` never gave an accepted value within {timeout_s} s (got: {fetched})\n"
        f"{process.describe()}\n\n{daemon.describe()}",
        pytrace=False,
    )


def _armed_in_heartbeat(process, daemon) -> bool:
    for _ in range(6):
        since = len(process.output)
        process.send_line("status HEARTBEAT")
        found = process.output.wait_for(HEARTBEAT_LINE, 0.5, since=since)
        if found is not None:
            return bool(int(found[2]["base_mode"]) & MAV_MODE_FLAG_SAFETY_ARMED)
    pytest.fail(f"{process.name} never showed a HEARTBEAT\n{process.describe()}\n\n{daemon.describe()}",
                pytrace=False)


# ---------------------------------------------------------------------------------------------
# A pymavlink ground station without the key


class KeylessClient:
    """A pymavlink ground station on one UDP socket, MAVLink2, no signing; records what it gets."""

    def __init__(self, port: int) -> None:
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=KEYLESS_SYSID, source_component=KEYLESS_COMPID
        )
        self.conn.mav = M.MAVLink(self.conn, srcSystem=KEYLESS_SYSID, srcComponent=KEYLESS_COMPID)
        self.conn.mav.robust_parsing = True
        self.conn.first_byte = False
        self.received: list = []

    def close(self) -> None:
        self.conn.close()

    def pump(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while (left := deadline - time.monotonic()) > 0:
            msg = self.conn.recv_match(blocking=True, timeout=min(left, 0.1))
            if msg is not None and msg.get_type() != "BAD_DATA":
                self.received.append(msg)

    def from_vehicle(self, kind: str) -> list:
        return [m for m in self.received
                if m.get_type() == kind and (m.get_srcSystem(), m.get_srcComponent()) == VEHICLE]

    def heartbeat(self) -> None:
        self.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def arm(self) -> None:
        self.conn.mav.command_long_send(*VEHICLE, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)

    def param_set(self, name: str, value: float) -> None:
        self.conn.mav.param_set_send(*VEHICLE, name.encode(), value, M.MAV_PARAM_TYPE_INT16)

    def param_read(self, name: str) -> None:
        self.conn.mav.param_request_read_send(*VEHICLE, name.encode(), -1)


# ---------------------------------------------------------------------------------------------


def test_mavproxy_sets_up_signing_on_a_trusted_link_then_only_key_holders_are_obeyed(
    spawn, gcsd_daemon, tmp_path
):
    daemon = gcsd_daemon({"signing": {"key": None, "require": True}, "channels": _channels()})

    # 1. MAVProxy on the unsigned_ok channel installs the key.
    trusted = _start_mavproxy(spawn, tmp_path, daemon.port("trusted"), "mavproxy-trusted",
                              f"--source-system={TRUSTED_MAVPROXY_SYSID}")
    _expect(trusted, daemon, r"Detected vehicle 1:1 on link 0", DETECT_WAIT_S, 0, "the vehicle")
    since = len(trusted.output)
    trusted.send_line(f"signing setup {PASSPHRASE}")
    _expect(trusted, daemon, r"Sent secret_key", TEXT_WAIT_S, since, "that it sent SETUP_SIGNING")
    _expect(trusted, daemon, r"Setup signing key", TEXT_WAIT_S, since, "that it signs its link")
    _expect(trusted, daemon, r"Signing enabled", TEXT_WAIT_S, since, "gcsd's STATUSTEXT 'Signing enabled'")

    # 2. A ground station without the key, on the plain channel: heard nothing it says.
    keyless = KeylessClient(daemon.port("gcs"))
    try:
        before = _status(daemon)
        started = time.monotonic()
        sent = 0
        while time.monotonic() - started < NO_ANSWER_WAIT_S:
            keyless.heartbeat()
            keyless.arm()
            keyless.param_set(PARAM, KEYLESS_VALUE)
            keyless.param_read(PARAM)
            sent += 4
            keyless.pump(0.5)
        after = _status(daemon)
    finally:
        keyless.close()
    # No amplification (SPEC "Channels"): a source of rejected frames is never served, not even
    # the signed telemetry or a STATUSTEXT; the rejections are explained by `gcsd status` (below)
    # and by a STATUSTEXT to the stations the channel does serve.
    assert keyless.from_vehicle("HEARTBEAT") == [], keyless.from_vehicle("HEARTBEAT")
    assert not keyless.from_vehicle("COMMAND_ACK"), keyless.from_vehicle("COMMAND_ACK")
    assert not keyless.from_vehicle("PARAM_VALUE"), keyless.from_vehicle("PARAM_VALUE")
    assert not keyless.from_vehicle("STATUSTEXT"), keyless.from_vehicle("STATUSTEXT")
    assert after["trusted"]["packets_out"] > before["trusted"]["packets_out"], "the trusted link was served meanwhile"
    rejected = (after["gcs"]["signature_reject_reasons"].get("unsigned", 0)
                - before["gcs"]["signature_reject_reasons"].get("unsigned", 0))
    assert rejected == sent, f"{sent} unsigned packets sent, {rejected} counted as rejected: {after['gcs']}"
    assert after["gcs"]["signature_rejects"] - before["gcs"]["signature_rejects"] == sent, after["gcs"]
    assert after["trusted"]["signature_rejects"] == 0, after["trusted"]

    # 3. MAVProxy with the key on the plain channel controls the vehicle.
    signed = _start_mavproxy(spawn, tmp_path, daemon.port("gcs"), "mavproxy-signed")
    signed.send_line(f"signing key {PASSPHRASE}")
    _expect(signed, daemon, r"Setup signing key", DETECT_WAIT_S, 0, "that it signs its link")
    _expect(signed, daemon, r"Detected vehicle 1:1 on link 0", DETECT_WAIT_S, 0, "the vehicle")

    old = _fetched_value(signed, daemon, PARAM, lambda v: True, SET_WAIT_S)
    assert old != KEYLESS_VALUE, f"the keyless client's PARAM_SET {PARAM} {KEYLESS_VALUE} was obeyed"
    assert old != 3, f"{PARAM} must start at another value than the one this test sets"
    since = len(signed.output)
    signed.send_line(f"param set {PARAM} 3")
    _fetched_value(signed, daemon, PARAM, lambda v: v == 3, SET_WAIT_S)
    assert signed.output.wait_for(rf"Failed to set {PARAM}", 0.0, since=since) is None, signed.describe()
    # the other client (another link, another signing stream) reads the same value
    _fetched_value(trusted, daemon, PARAM, lambda v: v == 3, SET_WAIT_S)

    since = len(signed.output)
    signed.send_line("arm throttle")
    _expect(signed, daemon, r"Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED", ACK_WAIT_S, since,
            "arming accepted")
    _expect(signed, daemon, r"(?:^|> )ARMED$", HEARTBEAT_STATE_WAIT_S, since, "the heartbeat's armed flag")
    assert _armed_in_heartbeat(signed, daemon)

    # 4. No new key while armed, even from the trusted link; the refusal reaches the sender.
    since = len(trusted.output)
    trusted.send_line("signing setup another-passphrase")
    _expect(trusted, daemon, r"Won't setup signing when armed", TEXT_WAIT_S, since,
            "gcsd's STATUSTEXT refusing SETUP_SIGNING while armed")
    trusted.send_line(f"signing key {PASSPHRASE}")  # MAVProxy switched its own key anyway: switch it back

    # The key did not change: the key holder still commands the vehicle.
    since = len(signed.output)
    signed.send_line("disarm")
    _expect(signed, daemon, r"Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED", ACK_WAIT_S, since,
            "disarming accepted with the original key")
    _expect(signed, daemon, r"(?:^|> )DISARMED$", HEARTBEAT_STATE_WAIT_S, since,
            "the heartbeat's disarmed state")

    final = _status(daemon)
    assert final["gcs"]["signature_reject_reasons"].get("bad_signature", 0) == 0, final["gcs"]
    assert final["gcs"]["signature_reject_reasons"].get("replay", 0) == 0, final["gcs"]

    for process in (signed, trusted):
        process.stop(5.0, end_of_input_first=True)


# ---------------------------------------------------------------------------------------------
# MAVSDK


async def _first(stream, accept, timeout_s: float, what: str):
    seen = []
    try:
        async with aclosing(stream) as values, asyncio.timeout(timeout_s):
            async for value in values:
                if accept(value):
                    return value
                seen.append(value)
    except TimeoutError:
        pass
    pytest.fail(f"MAVSDK reported no {what} within {timeout_s} s; last seen: {[str(v) for v in seen[-3:]]}",
                pytrace=False)


async def test_mavsdk_is_refused_on_a_signed_channel_and_arms_on_an_unsigned_ok_one(gcsd_daemon):
    daemon = gcsd_daemon({"signing": {"key": KEY.hex(), "require": True}, "channels": _channels()})

    # On the signed channel MAVSDK has no key: everything it sends is rejected, so it is never
    # served (no amplification, SPEC "Channels") and finds no autopilot; gcsd counts each reject.
    before = await asyncio.to_thread(_status, daemon)
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        await mavsdk.add_any_connection(f"udpout://127.0.0.1:{daemon.port('gcs')}")
        system = await mavsdk.first_autopilot(timeout_s=DISCOVERY_WAIT_S)
        assert system is None, f"a keyless MAVSDK was served on the signed channel\n{daemon.describe()}"
    finally:
        mavsdk.destroy()
    after = await asyncio.to_thread(_status, daemon)
    rejected = (after["gcs"]["signature_reject_reasons"].get("unsigned", 0)
                - before["gcs"]["signature_reject_reasons"].get("unsigned", 0))
    assert rejected >= 3, f"MAVSDK's heartbeats were not counted as unsigned rejects: {after['gcs']}"
    assert after["gcs"]["peers"] == 0 and after["gcs"]["packets_out"] == before["gcs"]["packets_out"]

    # On the unsigned_ok channel it works.
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        await mavsdk.add_any_connection(f"udpout://127.0.0.1:{daemon.port('trusted')}")
        system = await mavsdk.first_autopilot(timeout_s=DISCOVERY_WAIT_S)
        assert system is not None, f"no autopilot on the unsigned_ok channel\n{daemon.describe()}"
        telemetry, action = TelemetryAsync(system), ActionAsync(system)
        try:
            await _first(telemetry.subscribe_gps_info(), lambda g: g.fix_type >= FixType.FIX_3D,
                         TELEMETRY_WAIT_S, "3D fix")
            try:
                await action.arm()
            except ActionError as error:
                pytest.fail(f"arm() on the unsigned_ok channel failed: {error}\n{daemon.describe()}",
                            pytrace=False)
            await _first(telemetry.subscribe_armed(), lambda a: a is True, TELEMETRY_WAIT_S, "armed = True")
            try:
                await action.disarm()
            except ActionError as error:
                pytest.fail(f"disarm() failed: {error}\n{daemon.describe()}", pytrace=False)
        finally:
            telemetry.destroy()
            action.destroy()
    finally:
        mavsdk.destroy()
    final = await asyncio.to_thread(_status, daemon)
    assert final["trusted"]["signature_rejects"] == 0, final["trusted"]
