"""Crash safety: SIGKILL at random moments while parameters are written and missions uploaded.

Each round starts the daemon on the same state directory, has a ground station write
parameters and upload missions as fast as the daemon acknowledges them, and kills the daemon
with SIGKILL after a random delay. Every state file must then be whole: the .parm file parses
completely, the mission file is a valid QGC WPL 110 plan equal to one of the plans that were
uploaded (the old one or the new one), never torn or empty. GCSD_KILL_ROUNDS (default 40).

Parameters are written behind (services/params.py): at start (the boot count), then at most once
a second while sets arrive, so a round drives for 0.2 to 1.3 s to kill the daemon before, during
and after the coalesced write at about one second. Each round waits for its own daemon's control
socket (the one a SIGKILL left behind is removed first), and counts as "during writes" when a
state file changed while it was driven.
"""

from __future__ import annotations

import os
import random
import signal
import socket
import subprocess
import sys
import time

import pytest
import yaml

from gcsd.vehicle.mission import wpl
from gcsd.vehicle.params.parmfile import read_parm

from .helpers import Client, M, pump

ROUNDS = int(os.environ.get("GCSD_KILL_ROUNDS", "40"))
VEHICLE = (1, 1)


def plan(n: int) -> list:
    return [
        M.MAVLink_mission_item_int_message(*VEHICLE, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_CMD_NAV_WAYPOINT,
                                           0, 1, 0, 0, 0, 0, int(-35.36e7) + seq * 100 + n, int(149.16e7), 10.0 + n)
        for seq in range(n)
    ]


def drive(c: Client, rng: random.Random, until: float) -> None:
    """Write parameters and upload plans of varying length until `until` (or the daemon dies)."""
    while time.monotonic() < until:
        c.send(M.MAVLink_param_set_message(*VEHICLE, b"RC%d_TRIM" % rng.randint(1, 16),
                                           float(rng.randint(1400, 1600)), M.MAV_PARAM_TYPE_INT16))
        items = plan(rng.randint(2, 12))
        c.send(M.MAVLink_mission_count_message(*VEHICLE, len(items), 0))
        seen = c.mark()
        end = min(until, time.monotonic() + 1.0)
        while time.monotonic() < end:
            pump([c], 0.01)
            done = False
            for r in c.received[seen:]:
                if r.type in ("MISSION_REQUEST", "MISSION_REQUEST_INT") and r.msg.seq < len(items):
                    c.send(items[r.msg.seq])
                elif r.type == "MISSION_ACK":
                    done = True
            seen = len(c.received)
            if done:
                break


@pytest.mark.fault
def test_sigkill_at_random_moments_never_leaves_a_torn_state_file(tmp_path):
    state = tmp_path / "state"
    rng = random.Random(1122)
    valid_plans = {()}  # what the mission file may hold: nothing yet, or an uploaded plan
    for n in range(2, 13):
        valid_plans.add(tuple(it.x for it in plan(n)[1:]))  # item 0 is home
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cfg = tmp_path / "gcsd.yaml"
    cfg.write_text(yaml.safe_dump({
        "state_dir": str(state), "log": {"level": "error", "format": "json"},
        "channels": [{"name": "gcs", "type": "udp-server", "address": f"127.0.0.1:{port}"}],
    }))
    kills_during_writes = 0
    env = {**os.environ, "XDG_RUNTIME_DIR": str(tmp_path / "run")}  # killed daemons' registrations stay here
    for round_ in range(ROUNDS):
        (state / "gcsd.sock").unlink(missing_ok=True)  # left by the last SIGKILL: wait for this round's
        proc = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(cfg)], env=env,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        c = Client(f"udpout:127.0.0.1:{port}", 255, 190)
        try:
            deadline = time.monotonic() + 10
            while not (state / "gcsd.sock").exists():
                assert proc.poll() is None and time.monotonic() < deadline, f"round {round_}: no start"
                time.sleep(0.01)
            mtimes = {p.name: p.stat().st_mtime_ns for p in state.glob("*") if p.is_file()}
            drive(c, rng, time.monotonic() + rng.uniform(0.2, 1.3))
            proc.send_signal(signal.SIGKILL)
            proc.wait(5)
            changed = {p.name for p in state.glob("*") if p.is_file() and mtimes.get(p.name) != p.stat().st_mtime_ns}
            kills_during_writes += bool(changed)
        finally:
            c.close()
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        values, problems = read_parm(state / "mav.parm")
        assert not problems, f"round {round_}: torn parameter file {problems}"
        assert "STAT_BOOTCNT" in values
        mission = state / "mission.waypoints"
        if mission.exists():
            items = wpl.loads(mission.read_text())
            assert tuple(it.x for it in items[1:]) in valid_plans, f"round {round_}: unknown plan"
    print(f"{ROUNDS} kills, {kills_during_writes} of them after state files had changed in that round")
    assert kills_during_writes > ROUNDS // 3
