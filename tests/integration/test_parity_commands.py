"""COMMAND_ACK parity with ArduPilot SITL: every MAV_CMD of the probe's table, COMMAND_LONG with all
seven params 0, disarmed, to the real daemon over UDP (pymavlink), for copter, plane and rover.

The expected results are ArduPilot's (`data/ardupilot/{vehicle}-probe.json`, copied from the shared captures); agreement must
be at least 95 %, and every disagreement must be a row of docs/commands.md's table with the result
gcsd really gives (so the documentation cannot drift from the code). Between two commands the
vehicle is put back as the probe found it: disarmed (forced) and in its initial mode, because a
few commands act (a Solo "Fly" button arms, NAV_LAND switches to LAND).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import all as ALL  # the probe names commands newer than ardupilotmega.xml here

from gcsd.vehicle.types import vehicle_type

from .helpers import M, wait_for

REPO = Path(__file__).resolve().parents[2]
PROBES = Path(__file__).resolve().parent / "data" / "ardupilot"
DOC = REPO / "docs" / "commands.md"
RESULT_NAMES = {getattr(M, name): name[len("MAV_RESULT_"):] for name in dir(M)
                if name.startswith("MAV_RESULT_") and name != "MAV_RESULT_ENUM_END"}
FORCE = 21196
MIN_AGREEMENT = 0.95


def _probe(vehicle: str) -> dict[str, str]:
    table = json.loads((PROBES / f"{vehicle}-probe.json").read_text())["command_ack_zero_params_disarmed"]
    return {name: result[len("MAV_RESULT_"):] for name, result in table.items() if result is not None}


def _documented() -> dict[tuple[str, str], tuple[str, str]]:
    """(vehicle, command) -> (ArduPilot's result, gcsd's) from docs/commands.md's difference table."""
    rows = {}
    for line in DOC.read_text().splitlines():
        m = re.match(r"\|\s*(copter|plane|rover)\s*\|\s*(MAV_CMD_\w+)\s*\|\s*(\w+)\s*\|\s*(\w+)\s*\|", line)
        if m:
            rows[(m[1], m[2])] = (m[3], m[4])
    return rows


def _command(gcs, command: int, *params: float, timeout: float = 2.0) -> str | None:
    mark = gcs.mark()
    gcs.command_long(command, *params)
    r = wait_for(gcs, lambda r: r.type == "COMMAND_ACK" and r.msg.command == command and r.src == (1, 1),
                 timeout, since=mark)
    return None if r is None else RESULT_NAMES.get(r.msg.result, str(r.msg.result))


def _results(daemon, client, vehicle: str, names) -> dict[str, str | None]:
    d = daemon({"vehicle": {"type": vehicle},
                "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]})
    gcs = client(f"udpout:127.0.0.1:{d.port('gcs')}")
    gcs.heartbeat()
    assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == (1, 1), 3.0)
    initial_mode = vehicle_type(vehicle).initial_mode
    got = {}
    for name in names:
        got[name] = _command(gcs, getattr(ALL, name))
        assert _command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, FORCE) == "ACCEPTED", f"daemon gone after {name}?"
        assert _command(gcs, M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, initial_mode) == "ACCEPTED"
    return got


@pytest.mark.parametrize("vehicle", ["copter", "plane", "rover"])
def test_command_acks_with_zero_params_match_ardupilot_or_are_documented(daemon, client, vehicle):
    probe = _probe(vehicle)
    documented = _documented()
    got = _results(daemon, client, vehicle, sorted(probe))
    differences = {name: (probe[name], got[name]) for name in probe if got[name] != probe[name]}
    agreement = 1 - len(differences) / len(probe)
    print(f"{vehicle}: {len(probe) - len(differences)} of {len(probe)} COMMAND_ACK results agree "
          f"({100 * agreement:.1f} %)")
    undocumented = {name: d for name, d in differences.items() if documented.get((vehicle, name)) != d}
    assert not undocumented, f"differences from ArduPilot not in docs/commands.md (ArduPilot, gcsd): {undocumented}"
    assert agreement >= MIN_AGREEMENT
    stale = {name for (v, name) in documented if v == vehicle and name not in differences}
    assert not stale, f"docs/commands.md lists differences that no longer exist: {sorted(stale)}"


def test_plane_answers_do_change_altitude_with_zero_params_which_stopped_arduplane_sitl(daemon, client):
    """ArduPlane SITL aborted ("Should not be called on invalid location") on this command; gcsd answers."""
    got = _results(daemon, client, "plane", ["MAV_CMD_DO_CHANGE_ALTITUDE", "MAV_CMD_DO_CHANGE_ALTITUDE"])
    assert got["MAV_CMD_DO_CHANGE_ALTITUDE"] is not None
