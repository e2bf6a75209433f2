"""A DO_JUMP loop over a NAV item that completes at once, flown by the real daemon (issue 17,
item 6): the vehicle keeps flying, MISSION_CURRENT and HEARTBEAT keep coming, the CPU stays low."""

from __future__ import annotations

import time

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission import MissionItem

from .helpers import VEHICLE, is_ack, is_type, pump, udp_channel, udp_url, wait_for
from .mission_client import MissionClient
from .test_mission import HOME_ITEM, REL

LOOP_PLAN = [
    HOME_ITEM,
    MissionItem(M.MAV_CMD_NAV_TAKEOFF, REL, 0, 1, 0, 0, 0, 0, 0, 0, 10.0),
    MissionItem(M.MAV_CMD_NAV_DELAY, M.MAV_FRAME_MISSION, 0, 1, 0, 0, 0, 0, 0, 0, 0.0),
    MissionItem(M.MAV_CMD_DO_JUMP, M.MAV_FRAME_MISSION, 0, 1, 2.0, -1.0, 0, 0, 0, 0, 0.0),
]
AUTO = 3  # copter


def test_a_jump_loop_over_an_instant_nav_item_keeps_the_vehicle_flying_and_the_cpu_low(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    assert MissionClient(c).upload(LOOP_PLAN) == M.MAV_MISSION_ACCEPTED
    for command, params in ((M.MAV_CMD_COMPONENT_ARM_DISARM, (1,)),
                            (M.MAV_CMD_DO_SET_MODE, (M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, AUTO))):
        mark = c.mark()
        c.command_long(command, *params)
        assert wait_for(c, is_ack(command), since=mark).msg.result == M.MAV_RESULT_ACCEPTED
    assert wait_for(c, lambda r: r.type == "MISSION_ITEM_REACHED" and r.msg.seq == 1, timeout=20.0), "took off"
    mark = c.mark()
    cpu_before, wall_before = time.process_time(), time.monotonic()
    pump([c], 3.0)
    cpu_share = (time.process_time() - cpu_before) / (time.monotonic() - wall_before)
    got = c.since(mark)
    assert len([r for r in got if is_type("HEARTBEAT", VEHICLE)(r)]) >= 2
    current = [r.msg.seq for r in got if is_type("MISSION_CURRENT", VEHICLE)(r)]
    assert len(current) >= 2 and set(current) == {2}, current
    assert len([r for r in got if r.type == "MISSION_ITEM_REACHED" and r.msg.seq == 2]) >= 10, "the loop runs"
    alts = [r.msg.relative_alt / 1000 for r in got if is_type("GLOBAL_POSITION_INT", VEHICLE)(r)]
    assert alts and all(abs(a - 10.0) < 1.5 for a in alts), alts
    assert d.status()["errors"] == {}
    assert cpu_share < 0.25, f"the test process (daemon and client) used {cpu_share:.0%} of a core"
