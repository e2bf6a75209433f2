"""The mission service on the whole vehicle node with a float clock (vehicle_harness): what a
stalled upload does to the link, beyond the transfer's own machine (test_mission_transfer.py).

This is the fake-clock form of what tests/integration/test_mission.py once checked in 10 s of
real time: the re-requests back off from 250 ms to mission.retry_ms, the upload is cancelled 8 s
after the count, and the link's streams run 4x slower while it waits, then recover.
"""

from __future__ import annotations

import itertools

from pymavlink.dialects.v20 import ardupilotmega as M
from vehicle_harness import Harness

from gcsd.vehicle.mission import MissionItem

STEP_S = 0.01


def run(h: Harness, seconds: float) -> list[tuple[float, object]]:
    """Advance the clock in STEP_S steps; every frame sent, with the time it was sent."""
    out = []
    for _ in range(round(seconds / STEP_S)):
        mark = h.mark()
        h.run(STEP_S, step=STEP_S)
        out += [(h.t, m) for m in h.received[mark:]]
    return out


def rate_hz(sent: list, name: str, lo: float, hi: float) -> float:
    return len([m for t, m in sent if m.get_type() == name and lo <= t < hi]) / (hi - lo)


def test_a_stalled_upload_backs_off_slows_the_streams_then_is_cancelled_at_8_s_and_they_recover(tmp_path):
    h = Harness(tmp_path)
    h.run(2.0)
    warm = run(h, 2.0)
    before = rate_hz(warm, "ATTITUDE", warm[0][0], h.t)
    assert before > 2.0, "the link streams ATTITUDE (the control for 'slower')"

    start = h.t
    mark = h.mark()
    h.send(M.MAVLink_mission_count_message(1, 1, 3, 0))
    sent = [(start, m) for m in h.received[mark:]] + run(h, 9.0)
    requests = [(t - start, m.seq) for t, m in sent if m.get_type() in ("MISSION_REQUEST", "MISSION_REQUEST_INT")]
    assert {seq for _, seq in requests} == {0}
    times = [t for t, _ in requests]
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert abs(gaps[0] - 0.25) < 0.02 and abs(gaps[1] - 0.5) < 0.02, gaps
    assert all(abs(g - 1.0) < 0.02 for g in gaps[2:]), gaps

    acks = [(t - start, m.type) for t, m in sent if m.get_type() == "MISSION_ACK"]
    assert acks[0][1] == M.MAV_MISSION_OPERATION_CANCELLED and abs(acks[0][0] - 8.0) < 0.05, acks
    assert "Mission upload timeout" in [m.text for _, m in sent if m.get_type() == "STATUSTEXT"]

    during = rate_hz(sent, "ATTITUDE", start + 1.0, start + 7.0)
    assert during < before / 2.5, (before, during)
    after = run(h, 2.0)
    assert rate_hz(after, "ATTITUDE", after[0][0], h.t) > before * 0.8, "the streams recover after the abort"


def test_a_new_current_item_is_confirmed_by_mission_current_in_the_same_instant(tmp_path):
    """MISSION_SET_CURRENT and MAV_CMD_DO_SET_MISSION_CURRENT push MISSION_CURRENT with the new
    seq before the clock moves (its stream slot is seconds away); a refused one pushes nothing.
    The integration test (test_mission.py) awaits the message without timing it."""
    h = Harness(tmp_path)
    home = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 1)
    takeoff = MissionItem(M.MAV_CMD_NAV_TAKEOFF, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, z=20.0)
    h.node.plans.mission.replace((home, takeoff, takeoff, takeoff, takeoff))
    h.run(3.0)  # past the streams' first slots
    mark = h.mark()
    h.send(M.MAVLink_mission_set_current_message(1, 1, 3))
    assert [m.seq for m in h.of_type("MISSION_CURRENT", mark)] == [3]
    mark = h.mark()
    assert h.command(M.MAV_CMD_DO_SET_MISSION_CURRENT, 2) == M.MAV_RESULT_ACCEPTED
    assert [m.seq for m in h.of_type("MISSION_CURRENT", mark)] == [2]
    mark = h.mark()
    assert h.command(M.MAV_CMD_DO_SET_MISSION_CURRENT, 5) == M.MAV_RESULT_DENIED  # out of range
    h.send(M.MAVLink_mission_set_current_message(1, 1, 9))
    assert h.of_type("MISSION_CURRENT", mark) == []
    h.run(5.0)
    assert h.of_type("MISSION_CURRENT", mark), "the control: the stream itself sends it"


# --- a companion computer has no mission of its own (issue 27) --------------------------------

def test_a_companion_has_no_mission_home_or_plan_of_its_own(tmp_path):
    h = Harness(tmp_path, vehicle="companion")
    node = h.node
    mark = h.mark()
    h.send(M.MAVLink_mission_request_list_message(node.sysid, node.compid, M.MAV_MISSION_TYPE_MISSION))
    h.send(M.MAVLink_mission_request_list_message(node.sysid, 0, M.MAV_MISSION_TYPE_MISSION))
    h.send(M.MAVLink_mission_request_int_message(node.sysid, node.compid, 0, M.MAV_MISSION_TYPE_MISSION))
    h.send(M.MAVLink_mission_count_message(node.sysid, node.compid, 2, M.MAV_MISSION_TYPE_MISSION))
    h.run(0.5)
    acks = [m.type for m in h.of_type("MISSION_ACK", mark)]
    assert acks == [M.MAV_MISSION_UNSUPPORTED] * 2, "one for each request addressed to the companion by name"
    assert not h.of_type("MISSION_COUNT", mark) and not h.of_type("MISSION_ITEM_INT", mark), "no made-up home"
    assert node.plans.read_plan(M.MAV_MISSION_TYPE_MISSION) is None
    assert node.plans.write_plans({M.MAV_MISSION_TYPE_MISSION: ()}).result == M.MAV_MISSION_UNSUPPORTED
    assert not node.capabilities() & M.MAV_PROTOCOL_CAPABILITY_MISSION_INT
