"""Values a command, a guided target or a plan cannot honour (SPEC.md "Bad input", issue 11).

Every case here once stopped the daemon (a NaN home, a NaN guided target, a NaN loiter radius
that was stored and killed the daemon when flown and after every restart, an infinite fence
circle). Each is now refused at the edge with ArduPilot's code (COMMAND_ACK DENIED / FAILED,
MISSION_ACK INVALID_PARAMn), nothing is stored, and each test ends with the daemon answering
a parameter read on the same link (the positive control: a dead or stalled daemon fails).
"""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from gcsd.vehicle.mission import wpl
from gcsd.vehicle.mission.items import MissionItem

from .helpers import VEHICLE, Client, M, from_vehicle, is_ack, is_type, pump, udp_channel, udp_url, wait_for
from .mission_client import MissionClient

NAN, INF = math.nan, math.inf
HOME_LAT, HOME_LON, HOME_ALT = -35.363262, 149.165237, 584.0
COPTER_GUIDED = 4
IGNORE_ALL_BUT_POSITION = 0b110111111000
IGNORE_ALL_BUT_VELOCITY = 0b110111000111


def connect(daemon, client) -> Client:
    d = daemon({"channels": [udp_channel("gcs")]})
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    assert wait_for(c, from_vehicle), "nothing from the vehicle"
    return c


def answers(c: Client) -> bool:
    """The daemon is alive and serving this link: a parameter read is answered."""
    mark = c.mark()
    c.send(M.MAVLink_param_request_read_message(*VEHICLE, b"SYSID_THISMAV", -1))
    return wait_for(c, lambda r: r.type == "PARAM_VALUE" and r.src == VEHICLE, since=mark) is not None


def ack(c: Client, send, command: int) -> int | None:
    mark = c.mark()
    send()
    r = wait_for(c, is_ack(command), since=mark)
    return None if r is None else r.msg.result


def home(c: Client) -> tuple[float, float, float]:
    mark = c.mark()
    assert ack(c, lambda: c.command_long(M.MAV_CMD_GET_HOME_POSITION), M.MAV_CMD_GET_HOME_POSITION) == 0
    r = wait_for(c, is_type("HOME_POSITION", VEHICLE), since=mark)
    assert r is not None
    return r.msg.latitude / 1e7, r.msg.longitude / 1e7, r.msg.altitude / 1000.0


# --- DO_SET_HOME ----------------------------------------------------------------------------------


@pytest.mark.parametrize(("param", "value", "result"), [
    (5, NAN, M.MAV_RESULT_FAILED),  # a latitude set_home cannot take (the other one is given)
    (6, NAN, M.MAV_RESULT_FAILED),
    (7, NAN, M.MAV_RESULT_DENIED),  # ArduPilot's location_from_command_t refuses a NaN altitude
    (5, INF, M.MAV_RESULT_FAILED),
    (6, -INF, M.MAV_RESULT_FAILED),
    (7, INF, M.MAV_RESULT_DENIED),
    (7, 1e9, M.MAV_RESULT_DENIED),  # beyond ArduPilot's +-83 km
    (5, 91.0, M.MAV_RESULT_FAILED),
])
def test_set_home_by_command_long_with_a_bad_location_is_refused_and_home_kept(daemon, client, param, value,
                                                                                 result):
    c = connect(daemon, client)
    before = home(c)
    params = [0.0, 0, 0, 0, HOME_LAT + 0.001, HOME_LON + 0.001, 600.0]
    params[param - 1] = value
    assert ack(c, lambda: c.command_long(M.MAV_CMD_DO_SET_HOME, *params), M.MAV_CMD_DO_SET_HOME) == result
    assert home(c) == pytest.approx(before, abs=1e-6)
    assert answers(c)
    # a good location is still taken (the command itself works)
    good = [0.0, 0, 0, 0, HOME_LAT + 0.001, HOME_LON + 0.001, 600.0]
    assert ack(c, lambda: c.command_long(M.MAV_CMD_DO_SET_HOME, *good), M.MAV_CMD_DO_SET_HOME) == 0
    assert home(c) == pytest.approx((HOME_LAT + 0.001, HOME_LON + 0.001, 600.0), abs=1e-5)


@pytest.mark.parametrize("z", [NAN, INF, -INF])
def test_set_home_by_command_int_with_a_bad_altitude_is_denied(daemon, client, z):
    c = connect(daemon, client)
    before = home(c)
    result = ack(c, lambda: c.command_int(M.MAV_CMD_DO_SET_HOME, 0, x=int(HOME_LAT * 1e7) + 100,
                                          y=int(HOME_LON * 1e7), z=z), M.MAV_CMD_DO_SET_HOME)
    assert result == M.MAV_RESULT_DENIED
    assert home(c) == pytest.approx(before, abs=1e-6)
    assert answers(c)


def test_set_home_here_ignores_whatever_the_unused_location_holds(daemon, client):
    # param1 1: "use the current position"; ArduPilot never looks at params 5-7 then
    c = connect(daemon, client)
    result = ack(c, lambda: c.command_long(M.MAV_CMD_DO_SET_HOME, 1, 0, 0, 0, NAN, INF, NAN), M.MAV_CMD_DO_SET_HOME)
    assert result == M.MAV_RESULT_ACCEPTED
    assert all(math.isfinite(v) for v in home(c))
    assert answers(c)


# --- other commands -------------------------------------------------------------------------------


@pytest.mark.parametrize(("command", "params", "result"), [
    (M.MAV_CMD_DO_SET_MODE, (1, NAN), M.MAV_RESULT_DENIED),  # NaN is no mode (0 would be STABILIZE)
    (M.MAV_CMD_COMPONENT_ARM_DISARM, (NAN,), M.MAV_RESULT_UNSUPPORTED),  # ArduPilot: neither 1 nor 0
    (M.MAV_CMD_DO_CHANGE_SPEED, (1, INF), M.MAV_RESULT_DENIED),
    (M.MAV_CMD_SET_MESSAGE_INTERVAL, (M.MAVLINK_MSG_ID_ATTITUDE, NAN), M.MAV_RESULT_DENIED),
    (M.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, 0, 0, 0, NAN), M.MAV_RESULT_DENIED),
    (M.MAV_CMD_DO_SET_ROI_LOCATION, (0, 0, 0, 0, HOME_LAT, HOME_LON, INF), M.MAV_RESULT_DENIED),
])
def test_a_nan_or_infinite_parameter_a_command_uses_is_refused(daemon, client, command, params, result):
    c = connect(daemon, client)
    assert ack(c, lambda: c.command_long(command, *params), command) == result
    assert answers(c)


def test_nan_in_parameters_a_command_does_not_use_is_ignored(daemon, client):
    # GET_HOME_POSITION uses none; ArduPilot and gcsd both ignore what they hold
    c = connect(daemon, client)
    assert ack(c, lambda: c.command_long(M.MAV_CMD_GET_HOME_POSITION, *[NAN] * 7),
               M.MAV_CMD_GET_HOME_POSITION) == M.MAV_RESULT_ACCEPTED
    assert answers(c)


# --- guided targets -------------------------------------------------------------------------------


def armed_in_guided(c: Client) -> None:
    assert ack(c, lambda: c.command_long(M.MAV_CMD_DO_SET_MODE, 1, COPTER_GUIDED), M.MAV_CMD_DO_SET_MODE) == 0
    assert ack(c, lambda: c.command_long(M.MAV_CMD_COMPONENT_ARM_DISARM, 1), M.MAV_CMD_COMPONENT_ARM_DISARM) == 0
    assert ack(c, lambda: c.command_long(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5), M.MAV_CMD_NAV_TAKEOFF) == 0


def local_target(mask: int, x=0.0, y=0.0, z=0.0, vx=0.0, vy=0.0, vz=0.0, afx=0.0, yaw=0.0):
    return M.MAVLink_set_position_target_local_ned_message(0, *VEHICLE, M.MAV_FRAME_LOCAL_OFFSET_NED, mask,
                                                           x, y, z, vx, vy, vz, afx, 0, 0, yaw, 0)


def global_target(mask: int, lat: int, lon: int, alt: float, yaw: float = 0.0):
    return M.MAVLink_set_position_target_global_int_message(0, *VEHICLE, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mask,
                                                            lat, lon, alt, 0, 0, 0, 0, 0, 0, yaw, 0)


def wp_dist_after(c: Client, msg, seconds: float = 1.0) -> list[int]:
    """Send a target, read for `seconds`: the NAV_CONTROLLER_OUTPUT wp_dist values that came."""
    mark = c.mark()
    c.send(msg)
    pump([c], seconds)
    return [r.msg.wp_dist for r in c.since(mark, "NAV_CONTROLLER_OUTPUT") if r.src == VEHICLE]


@pytest.mark.parametrize("bad", [
    local_target(IGNORE_ALL_BUT_POSITION, x=NAN, z=-5),
    local_target(IGNORE_ALL_BUT_POSITION, x=-300, y=INF, z=-5),
    local_target(IGNORE_ALL_BUT_POSITION & ~(1 << 10), x=-300, z=-5, yaw=NAN),  # taken, it would be 400 m away
    local_target(IGNORE_ALL_BUT_VELOCITY, vx=NAN),
    local_target(IGNORE_ALL_BUT_VELOCITY, vz=-INF),
    local_target(IGNORE_ALL_BUT_POSITION & ~(0b111 << 6), x=-300, z=-5, afx=NAN),
    global_target(IGNORE_ALL_BUT_POSITION, int(HOME_LAT * 1e7) + 9000, int(HOME_LON * 1e7), NAN),
    global_target(IGNORE_ALL_BUT_POSITION, 2_000_000_000, int(HOME_LON * 1e7), 10.0),
], ids=["local-x-nan", "local-y-inf", "local-yaw-nan", "velocity-nan", "velocity-inf", "accel-nan", "global-alt-nan",
        "global-lat-out-of-range"])
def test_a_guided_target_with_a_bad_value_is_dropped_and_the_old_target_kept(daemon, client, bad):
    c = connect(daemon, client)
    armed_in_guided(c)
    # a real target 100 m north: the vehicle reports the distance to it
    good = wp_dist_after(c, local_target(IGNORE_ALL_BUT_POSITION, x=100, z=-5))
    assert good and 80 <= good[-1] <= 110, good
    after = wp_dist_after(c, bad)
    assert after, "telemetry stopped after the bad target"
    assert all(abs(d - good[-1]) <= 15 for d in after), (good, after)  # still flying to the old target
    assert answers(c)


# --- plans ----------------------------------------------------------------------------------------


def waypoint(lat_offset: int = 0, **kw) -> MissionItem:
    item = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                       x=int(HOME_LAT * 1e7) + lat_offset, y=int(HOME_LON * 1e7), z=20.0)
    return replace(item, **kw)


def test_a_mission_item_with_a_nan_loiter_radius_is_refused_and_the_old_plan_kept(daemon, client, tmp_path):
    c = connect(daemon, client)
    mc = MissionClient(c)
    old = [waypoint(), waypoint(1000)]
    assert mc.upload(old) == M.MAV_MISSION_ACCEPTED
    bad = [waypoint(), waypoint(2000, command=M.MAV_CMD_NAV_LOITER_TURNS, param1=2, param3=NAN)]
    assert mc.upload(bad) == M.MAV_MISSION_INVALID_PARAM3
    got = mc.download()
    assert [(i.command, i.x) for i in got[1:]] == [(M.MAV_CMD_NAV_WAYPOINT, old[1].x)]
    saved = wpl.loads((tmp_path / "state" / "mission.waypoints").read_text())
    assert all(math.isfinite(v) for it in saved for v in (it.param1, it.param2, it.param3, it.param4, it.z))
    assert answers(c)


@pytest.mark.parametrize(("item", "result"), [
    (waypoint(1000, z=INF), M.MAV_MISSION_INVALID_PARAM7),
    (waypoint(1000, param2=-INF), M.MAV_MISSION_INVALID_PARAM2),
    (waypoint(1000, command=M.MAV_CMD_NAV_LOITER_TIME, param1=INF), M.MAV_MISSION_INVALID_PARAM1),
])
def test_mission_items_with_infinite_values_are_refused(daemon, client, item, result):
    c = connect(daemon, client)
    assert MissionClient(c).upload([waypoint(), item]) == result
    assert answers(c)


def test_a_waypoint_with_yaw_nan_is_accepted_as_arducopter_does(daemon, client):
    c = connect(daemon, client)
    mc = MissionClient(c)
    assert mc.upload([waypoint(), waypoint(1000, param4=NAN)]) == M.MAV_MISSION_ACCEPTED
    assert math.isnan(mc.download()[1].param4)
    assert answers(c)


@pytest.mark.parametrize("radius", [INF, NAN])
def test_a_fence_circle_of_radius_inf_or_nan_is_refused(daemon, client, radius):
    c = connect(daemon, client)
    mc = MissionClient(c)
    circle = MissionItem(M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_FRAME_GLOBAL_INT, param1=radius,
                         x=int(HOME_LAT * 1e7), y=int(HOME_LON * 1e7))
    assert mc.upload([circle], M.MAV_MISSION_TYPE_FENCE) == M.MAV_MISSION_INVALID_PARAM1
    assert mc.download(M.MAV_MISSION_TYPE_FENCE) == []
    assert mc.upload([MissionItem(M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_FRAME_GLOBAL_INT, param1=300.0,
                                  x=circle.x, y=circle.y)], M.MAV_MISSION_TYPE_FENCE) == M.MAV_MISSION_ACCEPTED
    assert answers(c)


def test_a_guided_fly_to_item_with_a_nan_altitude_is_refused(daemon, client):
    c = connect(daemon, client)
    armed_in_guided(c)
    mark = c.mark()
    c.send(M.MAVLink_mission_item_int_message(*VEHICLE, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_CMD_NAV_WAYPOINT,
                                              2, 1, 0, 0, 0, 0, int(HOME_LAT * 1e7) + 900, int(HOME_LON * 1e7), NAN, 0))
    r = wait_for(c, is_type("MISSION_ACK", VEHICLE), since=mark)
    assert r is not None and r.msg.type == M.MAV_MISSION_ERROR
    assert answers(c)


def test_a_stored_plan_holding_nan_is_rejected_at_start_and_the_daemon_runs(daemon, client, tmp_path):
    # a plan file as an older gcsd wrote it: a loiter radius NaN, which killed the daemon when flown
    state = tmp_path / "state"
    state.mkdir()
    plan = [waypoint(), waypoint(1000, command=M.MAV_CMD_NAV_LOITER_TURNS, param1=2, param3=NAN)]
    (state / "mission.waypoints").write_text(wpl.dumps(plan))
    c = connect(daemon, client)
    assert len(MissionClient(c).download()) <= 1  # home at most: the plan was not adopted
    assert (state / "mission.waypoints.invalid").exists()
    assert not (state / "mission.waypoints").exists()
    # nothing to fly: MISSION_START is refused, and the daemon carries on
    assert ack(c, lambda: c.command_long(M.MAV_CMD_MISSION_START), M.MAV_CMD_MISSION_START) == M.MAV_RESULT_FAILED
    assert answers(c)


@pytest.mark.parametrize(("param1", "result"), [
    (1, M.MAV_RESULT_ACCEPTED),  # reboot: the simulated vehicle restarts, the daemon does not exit
    (3, M.MAV_RESULT_ACCEPTED),
    (2, M.MAV_RESULT_UNSUPPORTED),  # shutdown: not something a peer may do to the daemon
    (NAN, M.MAV_RESULT_UNSUPPORTED),
])
def test_reboot_and_shutdown_commands_never_stop_the_daemon(daemon, client, param1, result):
    c = connect(daemon, client)
    assert ack(c, lambda: c.command_long(M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, param1),
               M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN) == result
    assert answers(c)


def test_a_location_command_in_a_local_frame_is_denied(daemon, client):
    c = connect(daemon, client)
    before = home(c)
    result = ack(c, lambda: c.command_int(M.MAV_CMD_DO_SET_HOME, 0, x=int(HOME_LAT * 1e7) + 100, y=int(HOME_LON * 1e7),
                                          z=10.0, frame=M.MAV_FRAME_LOCAL_NED), M.MAV_CMD_DO_SET_HOME)
    assert result == M.MAV_RESULT_DENIED
    assert home(c) == pytest.approx(before, abs=1e-6)
    assert answers(c)
