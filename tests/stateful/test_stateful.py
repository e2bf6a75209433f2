"""Stateful property test (issue #17): random interleavings of what ground stations, operators and
faults do to ONE real daemon (`gcsd run`, a subprocess: tests/stateful/daemon.py), with the
daemon's promises checked after every step.

Steps (hypothesis's RuleBasedStateMachine picks them and their arguments): ground stations join
(UDP or TCP, MAVLink 1 or 2, signed with the right key, unsigned, or with a wrong key) and leave;
SETUP_SIGNING from a trusted or untrusted link, with a new key, the zero key (off) and sane
timestamps; mission, fence and rally uploads (DO_JUMP loops included); arm, disarm, take off,
mode changes, mission start; parameter writes (any copter parameter, in range and at its limits;
NaN and infinity); SYSID_THISMAV (it takes effect at the next start); a TCP client cut mid-frame
or reset; garbage bytes on each channel; a clean restart (SIGTERM: exit 0) or a crash (SIGKILL).

Invariants after every step (`check`):
- the process runs; a station on the trusted channel is answered (PARAM_REQUEST_READ of a
  parameter the test wrote: the value it was acknowledged with, also across restarts);
- a station holding the current key is answered on the UDP and on the TCP channel (where the
  model says it must be: a key is set, or signing is not required);
- HEARTBEAT about 1 Hz: no gap over HEARTBEAT_GAP_S since the start, one in the last 2.5 s,
  7 to HEARTBEATS_IN_10_S_MAX in the last 10 s (a mode change or an arm pushes one at once);
- `gcsd status --json` (the control socket) answers and its `errors` are empty; no
  component_failed / command_failed / traceback in the log;
- the state files parse (mav.parm, the three plans, signing.key); an accepted plan is on disk
  as uploaded, a refused one left the old plan;
- RSS and open descriptors bounded (RSS_GROWTH_KB over the first reading; descriptors back to
  the first reading plus the test's open TCP connections within a few seconds).

Rules for the known defects of issue #17 were written first and skipped until their fixes landed
(`PENDING`/`ENABLED`: a rule for a defect not fixed yet starts in PENDING only and shows as a
skipped test naming its item).

Bounded: rounds of EXAMPLES_PER_ROUND examples of GCSD_STATEFUL_STEPS (default 15) steps, one
hypothesis run per round with seeds GCSD_STATEFUL_SEED (default fixed, so CI is repeatable),
+1, +2, ..., until GCSD_STATEFUL_SECONDS (default 45) have passed. A long hunt, niced so it does
not starve the machine (the "answers" bound GCSD_STATEFUL_ANSWER_S, default 3 s, is raised
because a niced daemon on a busy machine is slow, not dead):

    GCSD_STATEFUL_SECONDS=3600 GCSD_STATEFUL_SEED=$RANDOM GCSD_STATEFUL_STEPS=25 GCSD_STATEFUL_ANSWER_S=10 \\
        nice -n 10 .venv/bin/python -m pytest -q -p no:xdist tests/stateful -x

A failure prints hypothesis's steps (the falsifying example), the daemon's log tail and the
line that replays its round; the same seed replays the same steps (timing aside: the daemon
runs in real time, so a replay that passes is reported as flaky, with the first failure).
"""

from __future__ import annotations

import itertools
import math
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, Phase, seed, settings
from hypothesis import strategies as st
from hypothesis.stateful import (
    RuleBasedStateMachine,
    initialize,
    invariant,
    precondition,
    rule,
    run_state_machine_as_test,
)
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.wire.signing import EPOCH_2015_S, SAVE_INTERVAL_S, UNITS_PER_S

from . import plans
from .daemon import Daemon
from .station import Monitor, Station, now_units

SECONDS = float(os.environ.get("GCSD_STATEFUL_SECONDS", "45"))
SEED = int(os.environ.get("GCSD_STATEFUL_SEED", "20261126"))
STEPS = int(os.environ.get("GCSD_STATEFUL_STEPS", "15"))
EXAMPLES_PER_ROUND = 3  # the first example of a hypothesis run is its simplest one (cheap: see let_time_pass)

KEYS = {"k1": bytes(range(32)), "k2": bytes(range(100, 132)), "zero": bytes(32)}
HEARTBEAT_GAP_S = 3.0
HEARTBEATS_IN_10_S_MAX = 25  # 10 at 1 Hz, plus the ones pushed at once by mode changes and arming
CRASH_WINDOW_S = 2.5  # mav.parm is written at most once a second (services/params.py), plus margin
RSS_GROWTH_KB = 40_000
MAX_STATIONS = 5  # joined stations per run (the daemon serves max_peers 8 per channel)
ANSWER_S = float(os.environ.get("GCSD_STATEFUL_ANSWER_S", "3"))  # "it answers": within this (niced runs: more)
SIGNING_TEXTS = ("Signing enabled", "Signing disabled", "ERROR: Won't setup signing when armed",
                 "ERROR: signing setup needs a signed")  # the answers to SETUP_SIGNING (a long one is chunked)

GUIDED, AUTO = 4, 3  # ArduCopter's custom modes
REFUSED_ASKS = "SYSID_MYGCS"  # what a refused station asks for (the controls ask for other parameters)

PENDING = {
    "future_setup_signing": "issue #17 item 4: a SETUP_SIGNING from the future locks signed stations out",
    "overflowing_setup_signing": "issue #17 item 5: initial_timestamp 2**64-1 mutes the vehicle",
    "instant_jump_loop": "issue #17 item 6: DO_JUMP repeat -1 over NAV_DELAY 0 recurses in AUTO",
    "out_of_range_param": "issue #17 item 12: values outside the metadata range are refused, not stored",
    "second_instance": "issue #17 item 8: a second start on the same state_dir takes the control socket",
    "sighup": "issue #17 item 10: SIGHUP kills the daemon without a clean stop",
    "idle_tcp_flood": "issue #17 item 3: unauthenticated TCP connections exhaust the descriptors",
}
ENABLED = set(PENDING)  # every item's fix is on main (a rule for a new one starts in PENDING only)

def enabled(name: str):
    return lambda self: self.live and name in ENABLED


def f32(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


class GcsdMachine(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.d: Daemon | None = None
        self.monitor: Monitor | None = None
        self.stations: list[Station] = []
        self.operator = self.keyholder = self.tcp_keyholder = None
        self.params: dict[str, set[float]] = {}  # name -> values the daemon may hold
        self.plans: dict[int, int | None] = {}  # mission type -> items on disk (None: unknown)
        self.sysid = 1
        self.next_sysid: set[int] = {1}
        self.key: bytes | None = None
        self.configured_key: bytes | None = None
        self.require = False
        self.first_rss_kb = 0
        self.base_fds = 0
        self.link_ids = iter(range(1, 10_000))
        self.reads = 0
        self.acked: list[tuple[float, str, frozenset | None]] = []  # (when, name, what it may hold before)

    @property
    def live(self) -> bool:
        return self.d is not None

    # --- set-up ----------------------------------------------------------------------------------
    @initialize(require=st.booleans(), configured=st.sampled_from([None, "k1"]))
    def boot(self, require: bool, configured: str | None) -> None:
        self.require = require
        self.configured_key = self.key = KEYS[configured] if configured else None
        self.directory = tempfile.TemporaryDirectory(prefix="gcsd-stateful-")
        self.d = Daemon(Path(self.directory.name), require, self.configured_key)
        self._start()
        self.first_rss_kb = self.d.rss_kb()

    def _start(self) -> None:
        saved = self.d.state_files()["signing"] if self.d.state_dir.exists() else None
        self.floor_wall_s = 0.0  # new streams at or below the saved timestamp are refused as replays
        if saved is not None:
            self.floor_wall_s = EPOCH_2015_S + saved.timestamp / UNITS_PER_S + (0 if saved.clean else SAVE_INTERVAL_S)
        self.d.start()
        self.monitor = Monitor(self.d.ports["open"])
        self.monitor.start()
        self.operator = Station("udp", self.d.ports["open"], sysid=254)
        self.keyholder = Station("udp", self.d.ports["gcs"], sysid=252)
        self.tcp_keyholder = Station("tcp", self.d.ports["tcp"], sysid=251)
        self._resign()
        first = self._wait_heartbeat(since=self.monitor.started_at, timeout=10.0)
        assert first is not None, f"no HEARTBEAT after the start\n{self.d.log_tail()}"
        assert first[1] in self.next_sysid, f"the vehicle came up as {first[1]}, expected {self.next_sysid}"
        self.sysid = first[1]
        self.next_sysid = {self.sysid}
        self.base_fds = self.d.fds()

    def _resign(self) -> None:
        for s in (self.keyholder, self.tcp_keyholder):
            s.sign(self.key, link_id=next(self.link_ids))

    def _close_all(self) -> None:
        if self.monitor is not None:
            self.monitor.stop()
        for s in [*self.stations, self.operator, self.keyholder, self.tcp_keyholder]:
            if s is not None:
                s.close()
        self.stations = []

    def teardown(self) -> None:
        if self.d is None:
            return
        try:
            if self.d.alive():
                self.d.status_cli()  # the command itself answers, once per example
        finally:
            self._close_all()
            code = self.d.stop(signal.SIGTERM)
            self.directory.cleanup()
        assert code == 0, f"SIGTERM: exit {code}, not a clean stop\n{self.d.log_tail()}"

    # --- helpers ---------------------------------------------------------------------------------
    def _wait_heartbeat(self, since: float, timeout: float):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            beats, _ = self.monitor.snapshot()
            after = [b for b in beats if b[0] >= since]
            if after:
                return after[0]
            time.sleep(0.05)
        return None

    def _accepted_on_required_channel(self, key: bytes | None) -> bool:
        """Whether a station signing with `key` (None: unsigned) is served on gcs / tcp now."""
        if self.key is None:
            return not self.require
        if key == self.key:  # a true clock is above the floor the restart set (signing.py)
            return time.time() > self.floor_wall_s + 0.5
        return key is None and not self.require

    def _read_param(self, station: Station, name: str):
        req = M.MAVLink_param_request_read_message(self.sysid, 1, name.encode(), -1)
        return station.request(req, lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name
                               and m.get_srcSystem() == self.sysid, ANSWER_S)

    def _answered(self, station: Station, what: str) -> None:
        self.reads += 1
        names = sorted(self.params) or ["SYSID_THISMAV"]
        name = names[self.reads % len(names)]
        got = self._read_param(station, name)
        assert got is not None, f"{what}: PARAM_REQUEST_READ {name} not answered\n{self.d.log_tail()}"
        if name in self.params:
            assert f32(got.param_value) in self.params[name], (
                f"{name} reads {got.param_value}, acknowledged {sorted(self.params[name])}")

    def _command(self, station: Station, command: int, *params: float):
        p = list(params) + [0.0] * (7 - len(params))
        msg = M.MAVLink_command_long_message(self.sysid, 1, command, 0, *p)
        return station.request(msg, lambda m: m.get_type() == "COMMAND_ACK" and m.command == command, ANSWER_S,
                               resend_s=10.0)

    def _restart(self, sig: int) -> None:
        self._close_all()
        code = self.d.stop(sig)
        if sig == signal.SIGTERM:
            assert code == 0, f"SIGTERM: exit {code}, not a clean stop\n{self.d.log_tail()}"
        if self.configured_key is not None:
            self.key = self.configured_key  # the configured key wins at a start (signing.py)
        self._start()

    # --- rules: stations -------------------------------------------------------------------------
    @precondition(lambda self: self.live and len(self.stations) < MAX_STATIONS)
    @rule(kind=st.sampled_from(["udp", "tcp"]), signing=st.sampled_from(["key", "unsigned", "wrong"]),
          version=st.sampled_from([1, 2]))
    def join(self, kind: str, signing: str, version: int) -> None:
        channel = "tcp" if kind == "tcp" else "gcs"
        key = {"key": self.key, "unsigned": None, "wrong": KEYS["k2"] if self.key != KEYS["k2"] else KEYS["k1"]}[signing]
        version = 2 if key is not None else version
        s = Station(kind, self.d.ports[channel], sysid=230 + len(self.stations), version=version)
        s.sign(key, link_id=next(self.link_ids))
        s.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
        self.stations.append(s)
        served = self._accepted_on_required_channel(key) and not (version == 1 and self.require)
        if served:
            self._answered(s, f"a new {kind} station ({signing}, v{version})")
            return
        s.send(M.MAVLink_param_request_read_message(self.sysid, 1, REFUSED_ASKS.encode(), -1))
        control = self.tcp_keyholder if kind == "tcp" else self.keyholder
        if not self._accepted_on_required_channel(control.key):
            control = self.operator
        self._answered(control, "the control beside a refused station")  # its request went after ours
        got = [m for m in s.read(0.3)]
        if kind == "tcp" and not self.require:  # served from its connection on (serve_on_connect): no answer
            got = [m for m in got if m.get_type() == "PARAM_VALUE" and m.param_id == REFUSED_ASKS]
        got = [m.get_type() for m in got]
        assert got == [], f"a refused {kind} station ({signing}, v{version}) got {got}"  # SPEC: "gets nothing"

    @precondition(lambda self: self.live and self.stations)
    @rule(index=st.integers(0, MAX_STATIONS - 1))
    def leave(self, index: int) -> None:
        self.stations.pop(index % len(self.stations)).close()

    @precondition(lambda self: self.live)
    @rule(how=st.sampled_from(["half_frame", "reset", "garbage"]), data=st.binary(min_size=1, max_size=300))
    def tcp_fault(self, how: str, data: bytes) -> None:
        sock = socket.create_connection(("127.0.0.1", self.d.ports["tcp"]), timeout=2.0)
        if how == "half_frame":
            sock.sendall(self.operator.pack(M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))[:7])
        elif how == "garbage":
            sock.sendall(data)
        if how == "reset":
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        sock.close()

    @precondition(lambda self: self.live)
    @rule(channel=st.sampled_from(["gcs", "open"]), data=st.binary(min_size=1, max_size=600))
    def udp_garbage(self, channel: str, data: bytes) -> None:
        station = self.operator if channel == "open" else self.keyholder
        station.write(data)

    # --- rules: signing --------------------------------------------------------------------------
    @precondition(lambda self: self.live)
    @rule(via=st.sampled_from(["open", "keyholder", "unsigned_gcs"]), key=st.sampled_from(sorted(KEYS)),
          timestamp=st.sampled_from(["now", "zero", "past"]))
    def setup_signing(self, via: str, key: str, timestamp: str) -> None:
        ts = {"now": 0.0, "zero": None, "past": -86400.0}[timestamp]
        initial = 0 if ts is None else now_units(ts)
        self._setup_signing(via, KEYS[key], initial)

    def _setup_signing(self, via: str, key: bytes, initial: int) -> None:
        msg = M.MAVLink_setup_signing_message(self.sysid, 1, key, initial)
        if via == "unsigned_gcs":
            station = Station("udp", self.d.ports["gcs"], sysid=250)
            self.stations.append(station)
        else:
            station = self.operator if via == "open" else self.keyholder
        trusted = via == "open" or (via == "keyholder" and self.key is not None)
        reaches = via == "open" or self._accepted_on_required_channel(station.key)
        got = station.request(msg, lambda m: m.get_type() == "STATUSTEXT" and m.text.startswith(SIGNING_TEXTS),
                              ANSWER_S, resend_s=10.0)
        if not reaches:
            assert got is None, f"SETUP_SIGNING over a refused link was answered: {got.text}"
            return
        assert got is not None, f"SETUP_SIGNING ({via}) got no answer\n{self.d.log_tail()}"
        if not trusted:
            assert got.text.startswith("ERROR: signing setup needs"), f"untrusted SETUP_SIGNING: {got.text}"
            return
        assert "needs a signed" not in got.text, f"trusted SETUP_SIGNING refused: {got.text}"
        if got.text.startswith("Signing"):
            new_key = None if key == bytes(32) else key
            if new_key != self.key:
                self.floor_wall_s = 0.0  # a new key forgets the streams and the floor (signing.py)
            self.key = new_key
            self._resign()

    @precondition(enabled("future_setup_signing"))
    @rule(days=st.sampled_from([1, 365]))
    def future_setup_signing(self, days: int) -> None:
        self._setup_signing("open", KEYS["k1"], now_units(days * 86400.0))

    @precondition(enabled("overflowing_setup_signing"))
    @rule(initial=st.sampled_from([2**64 - 1, 2**48, 2**48 - 1]))
    def overflowing_setup_signing(self, initial: int) -> None:
        self._setup_signing("open", KEYS["k1"], initial)

    # --- rules: plans and flight -----------------------------------------------------------------
    def _upload(self, mission_type: int, items: list) -> int | None:
        s = self.operator
        count = M.MAVLink_mission_count_message(self.sysid, 1, len(items), mission_type)
        last, end = count, time.monotonic() + 15.0
        while time.monotonic() < end:
            got = s.request(last, lambda m: m.get_type() in ("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK")
                            and getattr(m, "mission_type", 0) == mission_type and m.target_system == s.sysid,
                            0.5, resend_s=10.0)
            if got is None:
                continue
            if got.get_type() == "MISSION_ACK":
                return got.type
            it = items[got.seq]
            last = M.MAVLink_mission_item_int_message(
                self.sysid, 1, got.seq, it.frame, it.command, 0, it.autocontinue, it.param1, it.param2,
                it.param3, it.param4, it.x, it.y, it.z, mission_type)
        return None

    @precondition(lambda self: self.live)
    @rule(plan=plans.plan)
    def upload(self, plan) -> None:
        mission_type, items = plan
        result = self._upload(mission_type, items)
        assert result is not None, f"upload of {len(items)} items (type {mission_type}) never acknowledged"
        if result == M.MAV_MISSION_ACCEPTED:
            self.plans[mission_type] = len(items)
        self._check_plans()

    @precondition(enabled("instant_jump_loop"))
    @rule()
    def instant_jump_loop(self) -> None:
        assert self._upload(plans.MISSION, plans.instant_jump_loop()) == M.MAV_MISSION_ACCEPTED
        self.plans[plans.MISSION] = 4
        for command, params in ((M.MAV_CMD_DO_SET_MODE, (1, 3)),
                                (M.MAV_CMD_COMPONENT_ARM_DISARM, (1, 21196)), (M.MAV_CMD_MISSION_START, ())):
            self._command(self.operator, command, *params)
        time.sleep(2.0)

    @precondition(lambda self: self.live)
    @rule(action=st.sampled_from(["arm", "force_arm", "disarm", "force_disarm", "takeoff", "mission_start",
                                  "mode", "set_current"]),
          mode=st.integers(0, 30), seq=st.integers(0, 20), alt=st.floats(1.0, 50.0))
    def fly(self, action: str, mode: int, seq: int, alt: float) -> None:
        command, params = {
            "arm": (M.MAV_CMD_COMPONENT_ARM_DISARM, (1,)),
            "force_arm": (M.MAV_CMD_COMPONENT_ARM_DISARM, (1, 21196)),
            "disarm": (M.MAV_CMD_COMPONENT_ARM_DISARM, (0,)),
            "force_disarm": (M.MAV_CMD_COMPONENT_ARM_DISARM, (0, 21196)),
            "takeoff": (M.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, alt)),
            "mission_start": (M.MAV_CMD_MISSION_START, ()),
            "mode": (M.MAV_CMD_DO_SET_MODE, (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode)),
            "set_current": (M.MAV_CMD_DO_SET_MISSION_CURRENT, (seq,)),
        }[action]
        ack = self._command(self.operator, command, *params)
        assert ack is not None, f"{action}: no COMMAND_ACK\n{self.d.log_tail()}"

    @precondition(lambda self: self.live)
    @rule(alt=st.floats(2.0, 30.0), auto=st.booleans(), seconds=st.floats(0.5, 4.0))
    def take_off(self, alt: float, auto: bool, seconds: float) -> None:
        """What a ground station does to fly: GUIDED, arm, take off, then AUTO (the plan) or not."""
        steps = [(M.MAV_CMD_DO_SET_MODE, (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, GUIDED)),
                 (M.MAV_CMD_COMPONENT_ARM_DISARM, (1, 21196)), (M.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, alt))]
        if auto:
            steps.append((M.MAV_CMD_DO_SET_MODE, (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, AUTO)))
        for command, params in steps:
            assert self._command(self.operator, command, *params) is not None, f"{command}: no COMMAND_ACK"
        time.sleep(seconds)

    @precondition(lambda self: self.live)
    @rule(seconds=st.floats(0.0, 3.0))
    def let_time_pass(self, seconds: float) -> None:
        """The simplest rule (0 s): a run's first, simplest example is then about a second."""
        time.sleep(seconds)

    # --- rules: parameters -----------------------------------------------------------------------
    def _param_set(self, name: str, value: float):
        d = plans.DEFS[name]
        msg = M.MAVLink_param_set_message(self.sysid, 1, name.encode(), value, d.ptype)
        return self.operator.request(msg, lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name,
                                     ANSWER_S, resend_s=10.0)

    @precondition(lambda self: self.live)
    @rule(data=st.data(), name=st.sampled_from(plans.WRITTEN))
    def param_set(self, data, name: str) -> None:
        d = plans.DEFS[name]
        value = data.draw(st.one_of(plans.in_range(name), st.sampled_from([float("nan"), float("inf")])),
                          label="value")
        got = self._param_set(name, value)
        if not math.isfinite(value):
            assert got is None, f"{name} = {value} was answered with {got}"
            return
        assert got is not None, f"PARAM_SET {name} = {value}: no PARAM_VALUE\n{self.d.log_tail()}"
        if d.read_only:
            return
        assert f32(got.param_value) == f32(value), f"{name} = {value} acknowledged as {got.param_value}"
        self._acknowledged(name, value)

    def _acknowledged(self, name: str, value: float) -> None:
        before = self.params.get(name)
        self.acked.append((time.monotonic(), name, None if before is None else frozenset(before)))
        self.params[name] = {f32(value)}

    @precondition(enabled("out_of_range_param"))
    @rule(data=st.data(), name=st.sampled_from(plans.has_range))
    def out_of_range_param(self, data, name: str) -> None:
        value = data.draw(plans.out_of_range(name), label="value")
        got = self._param_set(name, value)
        assert got is not None and f32(got.param_value) == f32(value), f"{name} = {value} not stored: {got}"
        self._acknowledged(name, value)

    @precondition(lambda self: self.live)
    @rule(sysid=st.integers(1, 200))
    def set_sysid(self, sysid: int) -> None:
        got = self._param_set("SYSID_THISMAV", float(sysid))
        assert got is not None and got.param_value == sysid, f"SYSID_THISMAV = {sysid}: {got}"
        self.acked.append((time.monotonic(), "SYSID_THISMAV", frozenset(self.next_sysid)))
        self.next_sysid = {sysid}

    # --- rules: the process ----------------------------------------------------------------------
    @precondition(lambda self: self.live)
    @rule(crash=st.booleans())
    def restart(self, crash: bool) -> None:
        if crash:  # a value acknowledged within the write-behind interval may still be an older one
            for when, name, before in self.acked:
                if time.monotonic() - when >= CRASH_WINDOW_S:
                    continue
                if name == "SYSID_THISMAV":
                    self.next_sysid |= before
                elif before is None:
                    self.params.pop(name, None)  # what it held before is not known to the test
                elif name in self.params:
                    self.params[name] |= before
        self.acked.clear()
        self._restart(signal.SIGKILL if crash else signal.SIGTERM)

    @precondition(enabled("sighup"))
    @rule()
    def sighup(self) -> None:
        self.d.proc.send_signal(signal.SIGHUP)
        time.sleep(1.0)

    @precondition(enabled("second_instance"))
    @rule()
    def second_instance(self) -> None:
        out = subprocess.run([sys.executable, "-m", "gcsd", "run", "-c", str(self.d.config_path)],
                             check=False, capture_output=True, timeout=30, env=dict(os.environ, XDG_RUNTIME_DIR=str(
                                 self.d.directory / "run")))
        assert out.returncode != 0, "a second daemon on the same state_dir started"

    @precondition(enabled("idle_tcp_flood"))
    @rule()
    def idle_tcp_flood(self) -> None:
        socks = []
        try:
            for _ in range(1100):
                try:
                    socks.append(socket.create_connection(("127.0.0.1", self.d.ports["tcp"]), timeout=1.0))
                except OSError:
                    break
            self._answered(self.operator, "the trusted station during 1 100 idle TCP connections")
            assert self.d.status() is not None
        finally:
            for s in socks:
                s.close()

    # --- invariants ------------------------------------------------------------------------------
    @invariant()
    def check(self) -> None:
        if not self.live:
            return
        assert self.d.alive(), f"the daemon exited ({self.d.proc.returncode})\n{self.d.log_tail()}"
        self._answered(self.operator, "the trusted station")
        if self.tcp_keyholder.peer_closed():  # the daemon closes a connection it does not serve (10 s)
            self.tcp_keyholder = Station("tcp", self.d.ports["tcp"], sysid=251)
            self.tcp_keyholder.sign(self.key, link_id=next(self.link_ids))
        for s in (self.keyholder, self.tcp_keyholder):
            if self._accepted_on_required_channel(s.key):
                s.tx.signing.timestamp = max(s.tx.signing.timestamp, now_units())  # its clock is true
                self._answered(s, f"a {s.kind} station with the current key")
        status = self.d.status()
        assert status["errors"] == {}, f"errors counted: {status['errors']}\n{self.d.log_tail()}"
        bad = [r for r in self.d.records() if r.get("event") in ("component_failed", "command_failed")
               or "Traceback" in str(r.get("event", "")) or "exception" in r]
        assert not bad, f"exceptions logged: {bad[:3]}"
        self._check_heartbeats()
        self._check_plans()
        files = self.d.state_files()
        if self.key is not None and self.configured_key is None:
            assert files["signing"] is not None and files["signing"].key == self.key, "signing.key is not the key"
        self._check_resources()

    def _check_heartbeats(self) -> None:
        beats, _ = self.monitor.snapshot()
        times = [t for t, sysid, _ in beats if sysid == self.sysid]
        now = time.monotonic()
        assert times and now - times[-1] < 2.5, f"no HEARTBEAT for {now - (times or [0])[-1]:.1f} s"
        gaps = [b - a for a, b in itertools.pairwise(times)]
        assert max(gaps, default=0.0) < HEARTBEAT_GAP_S, f"HEARTBEAT gap of {max(gaps):.1f} s"
        if now - self.monitor.started_at > 12.0:  # about 1 Hz: no storm (a mode change, an arm or a
            recent = [t for t in times if t > now - 10.0]  # new peer pushes one at once, by design)
            assert 7 <= len(recent) <= HEARTBEATS_IN_10_S_MAX, f"{len(recent)} HEARTBEATs in the last 10 s"

    def _check_plans(self) -> None:
        files = self.d.state_files()
        for mission_type, count in self.plans.items():
            name = plans.PLAN_FILES[mission_type]
            on_disk = len(files.get(name, []))
            assert count is None or on_disk == count, f"{name}: {on_disk} items on disk, {count} accepted"

    def _check_resources(self) -> None:
        rss = self.d.rss_kb()
        assert rss - self.first_rss_kb < RSS_GROWTH_KB, f"RSS {self.first_rss_kb} -> {rss} kB"
        allowed = self.base_fds + sum(1 for s in self.stations if s.kind == "tcp" and not s.closed) + 4
        end = time.monotonic() + 3.0
        while (fds := self.d.fds()) > allowed and time.monotonic() < end:
            time.sleep(0.1)
        assert fds <= allowed, f"{fds} descriptors open, {allowed} expected at most"


@pytest.mark.slow
def test_gcsd_under_random_interleavings():
    """Rounds of EXAMPLES_PER_ROUND examples (one hypothesis run each, seeds SEED, SEED+1, ...)
    until SECONDS have passed: the budget is kept between runs, so no example behaves differently
    for the time it starts at (hypothesis replays a failing one and must get the same draws)."""
    end = time.monotonic() + SECONDS
    for round_ in itertools.count():
        round_seed = SEED + round_
        try:
            run_state_machine_as_test(seed(round_seed)(GcsdMachine), settings=settings(
                max_examples=EXAMPLES_PER_ROUND, stateful_step_count=STEPS, deadline=None, database=None,
                phases=[Phase.explicit, Phase.generate], suppress_health_check=list(HealthCheck)))
        except BaseException as exc:
            exc.add_note(f"replay: GCSD_STATEFUL_SEED={round_seed} GCSD_STATEFUL_STEPS={STEPS} "
                         f"GCSD_STATEFUL_SECONDS=1 pytest tests/stateful")
            raise
        if time.monotonic() >= end:
            break


if set(PENDING) - ENABLED:
    @pytest.mark.parametrize("name", sorted(set(PENDING) - ENABLED))
    def test_pending_rule(name):
        pytest.skip(f"rule {name} waits for its fix: {PENDING[name]}")
