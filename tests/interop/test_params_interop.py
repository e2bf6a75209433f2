"""Parameters with real ground stations: MAVProxy's `param` module and MAVSDK's `param` plugin.

MAVProxy runs as in test_mavproxy.py (headless, commands on stdin, `--non-interactive` not used),
with its default `param` and `ftp` modules. `--cmd "set param_ftp 0"` is applied at start-up,
before MAVProxy's own first fetch (1 s after start), so every download here is the
PARAM_REQUEST_LIST protocol; the FTP path (`@PARAM/param.pck`) is tested with the FTP service.
The observables are its console lines: "Requested parameter list", "Received N parameters"
(printed when it holds every index 0..param_count-1), `param status` ("Have N/M params") and
`param show NAME` ("NAME  VALUE", the last PARAM_VALUE received for it).

MAVSDK (4.x, C++ core through ctypes) chooses the C-cast parameter encoding for an ArduPilot
autopilot: integers travel as their float value. Ints that come back exact, and the daemon's own
PARAM_VALUE (read with pymavlink) holding the same numbers, show both ends agree on it.

The reference for every check is what the daemon itself says in PARAM_VALUE, read with pymavlink
(param_count, names, types and values), not numbers written into the test.
"""

from __future__ import annotations

import asyncio
import os
import re
import struct
import sys
import time
from pathlib import Path
from typing import Self

import pytest
import yaml
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as M

from .conftest import GCSD_START_TIMEOUT_S, GCSD_STOP_TIMEOUT_S, REPO_ROOT, GcsdDaemon

pytest.importorskip("MAVProxy", reason="MAVProxy is a test extra: pip install -e .[test]")
pytest.importorskip("mavsdk.asyncio", reason="mavsdk is a test extra: pip install -e .[test]")

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.param import ParamAsync, ParamError

from .conftest import expect_line as _expect
from .conftest import mavproxy_script as _mavproxy_script

pytestmark = pytest.mark.interop

VEHICLE = (1, 1)
CLIENT_SYSID, CLIENT_COMPID = 250, 190  # the pymavlink reference client (not MAVProxy's 255)
INT_TYPES = (M.MAV_PARAM_TYPE_INT8, M.MAV_PARAM_TYPE_INT16, M.MAV_PARAM_TYPE_INT32)
DETECT_WAIT_S = 10.0  # MAVProxy's start-up (imports) included
FETCH_WAIT_S = 10.0  # the list takes ~0.1 s on loopback; MAVProxy re-requests after 1 s quiet
SET_WAIT_S = 3.0  # MAVProxy retries a set once a second, 3 attempts
READ_WAIT_S = 3.0


def _f32(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


def _name(msg) -> str:
    raw = msg.param_id
    return (raw.decode("ascii", "replace") if isinstance(raw, bytes) else raw).split("\0", 1)[0]


# ---------------------------------------------------------------------------------------------
# The pymavlink reference client


class ParamClient:
    """A pymavlink ground station on one UDP socket, pinned to MAVLink2 (no version switching)."""

    def __init__(self, port: int) -> None:
        self.conn = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=CLIENT_SYSID, source_component=CLIENT_COMPID
        )
        self.conn.mav = M.MAVLink(self.conn, srcSystem=CLIENT_SYSID, srcComponent=CLIENT_COMPID)
        self.conn.mav.robust_parsing = True
        self.conn.first_byte = False

    def close(self) -> None:
        self.conn.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def connect(self, timeout_s: float = 5.0) -> None:
        """Send HEARTBEATs (a udp-server talks only to clients it heard) until the vehicle's arrives."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            msg = self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.2)
            if msg is not None and (msg.get_srcSystem(), msg.get_srcComponent()) == VEHICLE:
                return
        raise AssertionError(f"no HEARTBEAT from the vehicle within {timeout_s} s")

    def read(self, name: str, timeout_s: float = READ_WAIT_S):
        """PARAM_REQUEST_READ by name (index -1), re-sent every 0.5 s; the PARAM_VALUE or None."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.conn.mav.param_request_read_send(*VEHICLE, name.encode(), -1)
            until = min(deadline, time.monotonic() + 0.5)
            while (left := until - time.monotonic()) > 0:
                msg = self.conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=left)
                if msg is not None and _name(msg) == name:
                    return msg
        return None

    def download(self, timeout_s: float = 10.0) -> dict[str, tuple[int, float, int, int]]:
        """The whole list: NAME -> (index, value, type, param_count); re-requests missing indices."""
        by_index: dict[int, object] = {}
        count = None
        self.conn.mav.param_request_list_send(*VEHICLE)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and (count is None or len(by_index) < count):
            msg = self.conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
            if msg is None:
                if count is None:
                    self.conn.mav.param_request_list_send(*VEHICLE)
                else:
                    for index in sorted(set(range(count)) - set(by_index))[:10]:
                        self.conn.mav.param_request_read_send(*VEHICLE, b"", index)
                continue
            if (msg.get_srcSystem(), msg.get_srcComponent()) != VEHICLE:
                continue
            count = msg.param_count
            if 0 <= msg.param_index < count:
                by_index[msg.param_index] = msg
        assert count is not None and len(by_index) == count, (
            f"pymavlink download incomplete: {len(by_index)} of {count} in {timeout_s} s"
        )
        return {
            _name(m): (i, m.param_value, m.param_type, m.param_count) for i, m in sorted(by_index.items())
        }


def _param_count(port: int) -> int:
    with ParamClient(port) as client:
        client.connect()
        msg = client.read("SYSID_THISMAV")
        assert msg is not None, "no PARAM_VALUE for SYSID_THISMAV"
        return msg.param_count


# ---------------------------------------------------------------------------------------------
# MAVProxy


def _start_mavproxy(spawn, tmp_path: Path, port: int):
    """Headless MAVProxy with its default param and ftp modules, parameter download by list."""
    return spawn(
        [
            sys.executable,
            _mavproxy_script(),
            f"--master=udpout:127.0.0.1:{port}",
            "--no-state",
            "--default-modules=param,ftp",
            "--cmd=set param_ftp 0",
        ],
        name="mavproxy",
        cwd=tmp_path,
        env_overrides={"HOME": str(tmp_path)},
    )


def _shown_value(process, daemon, name: str, accept, timeout_s: float) -> str:
    """`param show NAME` until the value it prints is accepted; returns that value's text."""
    line = re.compile(rf"(?:^|> ){re.escape(name)}\s+(?P<value>\S+)")
    deadline = time.monotonic() + timeout_s
    shown = []
    while time.monotonic() < deadline:
        since = len(process.output)
        process.send_line(f"param show {name}")
        found = process.output.wait_for(line, 0.5, since=since)
        if found is not None:
            value = found[2]["value"]
            if accept(value):
                return value
            shown.append(value)
            time.sleep(0.2)
    pytest.fail(
        f"`param show {name}` never showed an accepted value within {timeout_s} s (shown: {shown})\n"
        f"{process.describe()}\n\n{daemon.describe()}",
        pytrace=False,
    )


def _start_stoppable_gcsd(spawn, tmp_path: Path, state_dir: Path, name: str) -> GcsdDaemon:
    """gcsd as the gcsd_daemon fixture starts it, but for the test to stop (the fixture's
    teardown counts a daemon that exited before it as a failure)."""
    config = {
        "state_dir": str(state_dir),
        "log": {"level": "info", "format": "json"},
        "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}],
    }
    config_path = tmp_path / f"{name}.yaml"
    config_path.write_text(yaml.safe_dump(config, sort_keys=False))
    pythonpath = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    pythonpath.append(str(REPO_ROOT / "src"))
    process = spawn(
        [sys.executable, "-m", "gcsd", "run", "-c", str(config_path)],
        name=name,
        cwd=tmp_path,
        env_overrides={"PYTHONPATH": os.pathsep.join(pythonpath)},
    )
    daemon = GcsdDaemon(process, config_path, config)
    found = process.output.wait_for(r'"event": "channel_opened"', GCSD_START_TIMEOUT_S)
    if found is None:
        pytest.fail(f"gcsd did not open its channel\n{daemon.describe()}", pytrace=False)
    address = re.search(r'"address": "([^"]+):(\d+)"', found[2].string)
    daemon.addresses["gcs"] = (address[1], int(address[2]))
    return daemon


def test_mavproxy_fetches_the_list_sets_and_shows_a_parameter_and_it_survives_a_restart(
    spawn, gcsd_daemon, tmp_path
):
    state_dir = tmp_path / "state"
    first = _start_stoppable_gcsd(spawn, tmp_path, state_dir, "gcsd-first")
    port = first.port("gcs")
    count = _param_count(port)

    mavproxy = _start_mavproxy(spawn, tmp_path, port)
    _expect(mavproxy, first, r"Detected vehicle 1:1 on link 0", DETECT_WAIT_S, 0, "the vehicle")

    since = len(mavproxy.output)
    mavproxy.send_line("param fetch")
    requested, requested_at, _ = _expect(
        mavproxy, first, r"Requested parameter list(?: \(ftp\))?$", 5.0, since, "that it requested the list"
    )
    assert not mavproxy.output.lines(requested)[0][1].endswith("(ftp)"), "param_ftp 0 was not honoured"
    _, received_at, received = _expect(
        mavproxy, first, r"Received (\d+) parameters$", FETCH_WAIT_S, requested, "a complete parameter list"
    )
    print(f"MAVProxy: param fetch complete {received_at - requested_at:.3f} s after the request")
    assert int(received[1]) == count, f"MAVProxy received {received[1]} parameters, the daemon has {count}"
    since = len(mavproxy.output)
    mavproxy.send_line("param status")
    _, _, status = _expect(mavproxy, first, r"Have (\d+)/(\d+) params", 3.0, since, "`param status`")
    assert (int(status[1]), int(status[2])) == (count, count), status[0]

    before = _shown_value(mavproxy, first, "SR0_EXTRA1", lambda v: True, 3.0)
    assert float(before) != 7, "SR0_EXTRA1 must start at another value than the one this test sets"
    mavproxy.send_line("param set SR0_EXTRA1 7")
    _shown_value(mavproxy, first, "SR0_EXTRA1", lambda v: float(v) == 7, SET_WAIT_S)

    # A clean stop, then a new daemon on the same state_dir.
    mavproxy.stop(5.0, end_of_input_first=True)
    code, already_exited = first.process.stop(GCSD_STOP_TIMEOUT_S)
    assert not already_exited and code == 0, f"gcsd stop: exit code {code}\n{first.describe()}"

    second = gcsd_daemon({"state_dir": str(state_dir)}, name="gcsd-second")
    with ParamClient(second.port("gcs")) as client:
        client.connect()
        msg = client.read("SR0_EXTRA1")
    assert msg is not None, f"no PARAM_VALUE for SR0_EXTRA1 after the restart\n{second.describe()}"
    assert msg.param_value == 7.0, msg
    assert msg.param_type == M.MAV_PARAM_TYPE_INT16, msg
    assert msg.param_count == count, msg


# ---------------------------------------------------------------------------------------------
# MAVSDK


async def test_mavsdk_param_plugin_gets_and_sets_ints_and_floats_exactly_and_gets_all(gcsd_daemon):
    daemon = gcsd_daemon()
    port = daemon.port("gcs")

    def reference() -> dict[str, tuple[int, float, int, int]]:
        with ParamClient(port) as client:
            client.connect()
            return client.download()

    before = await asyncio.to_thread(reference)
    count = next(iter(before.values()))[3]
    assert before["SR0_POSITION"][2] == M.MAV_PARAM_TYPE_INT16
    assert before["RC1_TRIM"][2] == M.MAV_PARAM_TYPE_INT16
    assert before["SERVO1_FUNCTION"][2] == M.MAV_PARAM_TYPE_INT16
    assert before["BATT_CAPACITY"][2] == M.MAV_PARAM_TYPE_INT32
    assert before["COMPASS_OFS_X"][2] == M.MAV_PARAM_TYPE_REAL32
    assert before["BATT_ARM_VOLT"][2] == M.MAV_PARAM_TYPE_REAL32

    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    param = None
    try:
        await mavsdk.add_any_connection(f"udpout://127.0.0.1:{port}")
        system = await mavsdk.first_autopilot(timeout_s=5.0)
        assert system is not None, f"no autopilot within 5 s\n{daemon.describe()}"
        param = ParamAsync(system)

        # Reads: the values the daemon sends, ints as ints.
        assert await param.get_param_int("SR0_POSITION") == before["SR0_POSITION"][1]
        assert await param.get_param_int("RC1_TRIM") == before["RC1_TRIM"][1]
        assert await param.get_param_int("BATT_CAPACITY") == before["BATT_CAPACITY"][1]
        assert await param.get_param_float("COMPASS_OFS_X") == before["COMPASS_OFS_X"][1]
        assert await param.get_param_float("BATT_ARM_VOLT") == before["BATT_ARM_VOLT"][1]
        with pytest.raises(ParamError):  # the daemon says REAL32; MAVSDK refuses to read it as an int
            await param.get_param_int("COMPASS_OFS_X")

        # Integer writes come back exact (C-cast both ways), negative and 6-digit ones included.
        int_sets = {"SR0_POSITION": 7, "RC1_TRIM": 1523, "SERVO1_FUNCTION": -1, "BATT_CAPACITY": 987_654}
        for name, value in int_sets.items():
            assert before[name][1] != value, f"{name} already holds {value}"
            try:
                await param.set_param_int(name, value)
            except ParamError as error:
                pytest.fail(
                    f"set_param_int({name}, {value}) failed: {error}\n{daemon.describe()}", pytrace=False
                )
            assert await param.get_param_int(name) == value, name

        # Float writes come back as the single-precision value.
        float_sets = {"COMPASS_OFS_X": 123.456, "BATT_ARM_VOLT": 10.5}
        for name, value in float_sets.items():
            try:
                await param.set_param_float(name, value)
            except ParamError as error:
                pytest.fail(
                    f"set_param_float({name}, {value}) failed: {error}\n{daemon.describe()}", pytrace=False
                )
            assert await param.get_param_float(name) == _f32(value), name

        started = time.monotonic()
        everything = await param.get_all_params()
        took = time.monotonic() - started
    finally:
        if param is not None:
            param.destroy()
        mavsdk.destroy()
    print(f"MAVSDK get_all_params: {count} parameters in {took:.3f} s")

    # What the daemon says now, and what MAVSDK got, must be the same list.
    after = await asyncio.to_thread(reference)
    for name, value in {**int_sets, **float_sets}.items():
        assert after[name][1] == _f32(value), f"daemon's {name} is {after[name][1]}, MAVSDK set {value}"
    ints = {p.name: p.value for p in everything.int_params}
    floats = {p.name: p.value for p in everything.float_params}
    assert not everything.custom_params
    assert len(ints) + len(floats) == count, f"MAVSDK got {len(ints)} + {len(floats)} of {count} parameters"
    assert set(ints) == {n for n, (_, _, t, _) in after.items() if t in INT_TYPES}
    assert set(floats) == {n for n, (_, _, t, _) in after.items() if t == M.MAV_PARAM_TYPE_REAL32}
    assert all(isinstance(v, int) for v in ints.values())
    live = {"STAT_RUNTIME"}  # the daemon's running-time counter moves while the list is read
    assert {n: float(v) for n, v in ints.items() if n not in live} == {n: after[n][1] for n in ints if n not in live}
    assert floats == {n: after[n][1] for n in floats}
    for name, value in {**int_sets, **float_sets}.items():
        got = ints.get(name, floats.get(name))
        assert got == _f32(value), f"get_all_params has {name} = {got}, set to {value}"
