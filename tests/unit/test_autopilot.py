"""The autopilot through the real vehicle node, with a float clock: missions and their DO and
CONDITION items, RTL to rally points, the fence, failsafes, guided messages, sticks."""

from __future__ import annotations

import itertools

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M
from vehicle_harness import Harness

from gcsd.vehicle.mission import MissionItem
from gcsd.vehicle.sim.geo import distance_m, offset

ACCEPTED, FAILED, DENIED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_FAILED, M.MAV_RESULT_DENIED
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


def wp(h: Harness, north: float, east: float, alt: float = 10.0, command=M.MAV_CMD_NAV_WAYPOINT, **params):
    lat, lon = offset(h.state.home_lat, h.state.home_lon, north, east)
    return MissionItem(command, REL, x=round(lat * 1e7), y=round(lon * 1e7), z=alt, **params)


def plan(h: Harness, *items: MissionItem) -> None:
    home = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 1)
    h.node.plans.mission.replace((home, *items))


def reached(h: Harness) -> list[int]:
    return [m.seq for m in h.of_type("MISSION_ITEM_REACHED")]


def flying(tmp_path, alt: float = 10.0, **config) -> Harness:
    h = Harness(tmp_path, config=config)
    h.mode("GUIDED")
    assert h.arm() == ACCEPTED
    assert h.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, alt) == ACCEPTED
    assert h.run(30, until=lambda: h.state.relative_alt_m > alt - 0.5)
    return h


def test_a_mission_reports_each_item_reached_in_order_and_ends_complete(tmp_path):
    h = Harness(tmp_path)
    plan(h, MissionItem(M.MAV_CMD_NAV_TAKEOFF, REL, z=10), wp(h, 20, 0), wp(h, 20, 20), wp(h, 0, 20),
         MissionItem(M.MAV_CMD_NAV_LAND, REL))
    h.arm()
    assert h.mode("AUTO") == ACCEPTED
    assert h.run(200, until=lambda: not h.state.armed)
    assert reached(h) == [1, 2, 3, 4, 5]
    current = h.node.plans.current_message()
    assert current.seq == 5 and current.mission_state == M.MISSION_STATE_COMPLETE
    # LAND at 0/0 lands where it is: within WPNAV_RADIUS (2 m) of the last waypoint
    assert distance_m(h.state.lat, h.state.lon, *offset(h.state.home_lat, h.state.home_lon, 0, 20)) < 2.5


def test_do_jump_repeats_its_target_the_given_number_of_times(tmp_path):
    h = flying(tmp_path)
    plan(h, wp(h, 10, 0), wp(h, 0, 10), MissionItem(M.MAV_CMD_DO_JUMP, param1=1, param2=2), wp(h, 0, 0))
    h.mode("AUTO")
    assert h.run(300, until=lambda: 4 in reached(h))
    assert reached(h) == [1, 2, 1, 2, 1, 2, 4]


def test_do_items_run_with_their_nav_item_and_conditions_hold_them(tmp_path):
    h = flying(tmp_path)
    plan(h, wp(h, 30, 0),
         MissionItem(M.MAV_CMD_DO_CHANGE_SPEED, param2=2.0),
         MissionItem(M.MAV_CMD_CONDITION_DELAY, param1=3.0),
         MissionItem(M.MAV_CMD_DO_SET_SERVO, param1=6, param2=1234),
         wp(h, 30, 30))
    h.mode("AUTO")
    h.run(1.0)
    assert h.node.autopilot.speed_ms == 2.0
    assert 6 not in h.state.servo_override  # held by the 3 s delay
    h.run(3.0)
    assert h.state.servo_override[6] == 1234
    mark = h.mark()
    h.run(1.0)  # SERVO_OUTPUT_RAW streams at 5 Hz by default
    assert h.of_type("SERVO_OUTPUT_RAW", mark)[-1].servo6_raw == 1234


def test_repeat_relay_toggles_the_relay_count_times(tmp_path):
    h = Harness(tmp_path)
    assert h.command(M.MAV_CMD_DO_REPEAT_RELAY, 2, 3, 1.0) == ACCEPTED
    states = []
    for _ in range(40):
        h.run(0.1)
        states.append(h.state.relays[2])
    changes = sum(1 for a, b in itertools.pairwise(states) if a != b)
    assert changes == 5 and states[-1] is False


def test_a_motor_output_cannot_be_taken_by_do_set_servo(tmp_path):
    h = Harness(tmp_path)
    assert h.command(M.MAV_CMD_DO_SET_SERVO, 1, 1500) == FAILED  # SERVO1_FUNCTION 33: motor 1
    assert h.command(M.MAV_CMD_DO_SET_SERVO, 9, 1700) == ACCEPTED


def test_loiter_turns_circles_the_point_the_given_number_of_times(tmp_path):
    h = flying(tmp_path)
    plan(h, wp(h, 0, 0, command=M.MAV_CMD_NAV_LOITER_TURNS, param1=2, param3=8), wp(h, 0, 30))
    h.mode("AUTO")
    far = []
    h.run(120, until=lambda: 1 in reached(h) or far.append(distance_m(
        h.state.lat, h.state.lon, h.state.home_lat, h.state.home_lon)))
    assert 1 in reached(h)
    circling = sorted(far[len(far) // 2:])
    assert circling[len(circling) // 2] == pytest.approx(8.0, abs=1.0)  # the median radius


def test_a_huge_loiter_radius_is_flown_as_the_largest_arducopter_stores(tmp_path):
    # finite but absurd (1e30 m): the orbit is ArduPilot's 2550 m at most, never a point off the planet
    h = flying(tmp_path)
    plan(h, wp(h, 0, 0, command=M.MAV_CMD_NAV_LOITER_TURNS, param1=1, param3=1e30))
    h.mode("AUTO")
    h.run(20)
    target = h.state.target
    assert target is not None
    assert distance_m(target[0], target[1], h.state.home_lat, h.state.home_lon) <= 2550 * 1.01


def test_rtl_goes_to_the_nearest_rally_point_and_lands_there(tmp_path):
    h = flying(tmp_path)
    lat, lon = offset(h.state.home_lat, h.state.home_lon, 40, 0)
    h.node.plans.rally.replace((MissionItem(M.MAV_CMD_NAV_RALLY_POINT, REL, x=round(lat * 1e7),
                                              y=round(lon * 1e7), z=15),))
    lat2, lon2 = offset(h.state.home_lat, h.state.home_lon, 60, 0)
    h.command_int(M.MAV_CMD_DO_REPOSITION, -1, 0, 0, 0, round(lat2 * 1e7), round(lon2 * 1e7), 10)
    h.run(60, until=lambda: distance_m(h.state.lat, h.state.lon, lat2, lon2) < 1)
    assert h.mode("RTL") == ACCEPTED
    assert h.run(200, until=lambda: not h.state.armed)
    assert distance_m(h.state.lat, h.state.lon, lat, lon) < 1.0


def test_a_fence_breach_switches_to_rtl_and_reports_it(tmp_path):
    h = flying(tmp_path)
    h.set_param("FENCE_ENABLE", 1)
    h.set_param("FENCE_ALT_MAX", 20)
    mark = h.mark()
    lat, lon = h.state.lat, h.state.lon
    h.command_int(M.MAV_CMD_DO_REPOSITION, -1, 0, 0, 0, round(lat * 1e7), round(lon * 1e7), 40)
    assert h.run(30, until=lambda: h.node.vehicle.mode_name(h.state.mode) == "RTL")
    assert any(t.startswith("Fence Breach: altitude fence") for t in h.texts(mark))
    assert h.state.relative_alt_m < 22
    status = h.node.link(h.channel)
    status.push(M.MAVLINK_MSG_ID_FENCE_STATUS)
    h.run(0.1)
    fs = h.of_type("FENCE_STATUS")[-1]
    assert fs.breach_count == 1 and fs.breach_type == M.FENCE_BREACH_MAXALT


def test_gcs_heartbeat_loss_triggers_the_gcs_failsafe_and_its_return_clears_it(tmp_path):
    h = flying(tmp_path)
    h.set_param("FS_GCS_ENABLE", 1)
    h.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
    mark = h.mark()
    h.run(4.0)
    assert "GCS Failsafe" not in h.texts(mark)
    h.run(2.0)
    assert "GCS Failsafe" in h.texts(mark)
    assert h.node.vehicle.mode_name(h.state.mode) == "RTL"
    h.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
    h.run(0.2)
    assert "GCS Failsafe Cleared" in h.texts(mark)


def test_a_low_battery_takes_the_configured_action_once(tmp_path):
    h = flying(tmp_path)
    h.set_param("BATT_FS_LOW_ACT", 2)  # copter: RTL
    h.set_param("BATT_LOW_MAH", 4990)  # 5000 mAh pack: low almost at once
    mark = h.mark()
    h.run(5)
    texts = [t for t in h.texts(mark) if t.startswith("Battery 1 is low")]
    assert len(texts) == 1
    assert h.node.vehicle.mode_name(h.state.mode) == "RTL"


def test_rc_override_moves_a_copter_only_from_the_gcs_sysid(tmp_path):
    h = flying(tmp_path)
    h.mode("LOITER")
    override = [65535] * 18
    override[1] = 1300  # pitch forward
    msg = M.MAVLink_rc_channels_override_message(1, 1, *override)
    h.send(msg, sysid=77)
    h.run(1.0)
    assert h.state.groundspeed_ms < 0.1
    h.send(M.MAVLink_rc_channels_override_message(1, 1, *override))
    h.run(2.0)
    assert h.state.groundspeed_ms > 1.0
    h.set_param("FS_THR_ENABLE", 0)  # no RC failsafe when the overrides lapse (test_rc_params.py)
    h.run(4.0)  # RC_OVERRIDE_TIME 3 s: released, it stops
    assert h.state.groundspeed_ms < 0.5


def test_set_position_target_global_int_is_followed_in_guided_only(tmp_path):
    h = flying(tmp_path)
    lat, lon = offset(h.state.home_lat, h.state.home_lon, 0, 25)
    msg = M.MAVLink_set_position_target_global_int_message(0, 1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                                           0b110111111000, round(lat * 1e7), round(lon * 1e7), 12,
                                                           0, 0, 0, 0, 0, 0, 0, 0)
    h.send(msg)
    assert h.run(30, until=lambda: distance_m(h.state.lat, h.state.lon, lat, lon) < 0.5)
    h.mode("LOITER")
    lat2, lon2 = offset(h.state.home_lat, h.state.home_lon, 0, 0)
    msg.lat_int, msg.lon_int = round(lat2 * 1e7), round(lon2 * 1e7)
    h.send(msg)
    h.run(5)
    assert distance_m(h.state.lat, h.state.lon, lat, lon) < 0.5


def test_local_ned_velocity_targets_stop_after_guid_timeout(tmp_path):
    h = flying(tmp_path)
    msg = M.MAVLink_set_position_target_local_ned_message(0, 1, 1, M.MAV_FRAME_LOCAL_NED, 0b110111000111,
                                                          0, 0, 0, 2.0, 0, 0, 0, 0, 0, 0, 0)
    h.send(msg)
    h.run(2.0)
    assert h.state.vn_ms == pytest.approx(2.0, abs=0.1)
    h.run(3.0)
    assert h.state.groundspeed_ms < 0.2


def test_calibration_answers_in_progress_then_accepted_and_refuses_a_second_one(tmp_path):
    h = Harness(tmp_path)
    assert h.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 1) == M.MAV_RESULT_IN_PROGRESS
    assert h.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 1) == M.MAV_RESULT_TEMPORARILY_REJECTED
    mark = h.mark()
    h.run(3.0)
    acks = [a for a in h.of_type("COMMAND_ACK", mark) if a.command == M.MAV_CMD_PREFLIGHT_CALIBRATION]
    assert [a.result for a in acks] == [M.MAV_RESULT_IN_PROGRESS, ACCEPTED]
    assert "Gyro calibration complete" in h.texts(mark)


def test_storage_format_empties_the_ftp_root_only(tmp_path):
    h = Harness(tmp_path)
    root = tmp_path / "state" / "ftp"
    root.mkdir(parents=True, exist_ok=True)
    (root / "logs").mkdir()
    (root / "logs" / "1.bin").write_bytes(b"x")
    assert h.command(M.MAV_CMD_STORAGE_FORMAT, 1, 0) == M.MAV_RESULT_UNSUPPORTED
    assert h.command(M.MAV_CMD_STORAGE_FORMAT, 1, 1) == M.MAV_RESULT_IN_PROGRESS
    h.run(2.0)
    assert list(root.iterdir()) == []
    assert (tmp_path / "state" / "mav.parm").exists()


def test_reboot_is_refused_armed_and_resets_the_vehicle_disarmed(tmp_path):
    h = flying(tmp_path)
    assert h.command(M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1) == FAILED
    h.mode("LAND")
    h.run(60, until=lambda: not h.state.armed)
    boots = h.node.params.get("STAT_BOOTCNT")
    assert h.command(M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, 1) == ACCEPTED
    assert h.node.params.get("STAT_BOOTCNT") == boots + 1
    assert h.node.vehicle.mode_name(h.state.mode) == "STABILIZE"


def test_a_plane_takes_off_with_nav_takeoff_in_takeoff_mode_and_loiters(tmp_path):
    h = Harness(tmp_path, vehicle="plane")
    h.arm()
    assert h.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 30) == ACCEPTED
    assert h.node.vehicle.mode_name(h.state.mode) == "TAKEOFF"
    assert h.run(60, until=lambda: h.state.relative_alt_m > 28)
    h.run(60)
    assert h.state.relative_alt_m == pytest.approx(30, abs=3) and not h.state.on_ground


def test_a_sub_cannot_take_off_and_surfaces_in_surface_mode(tmp_path):
    h = Harness(tmp_path, vehicle="sub")
    assert h.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10) == M.MAV_RESULT_UNSUPPORTED
    h.arm()
    h.mode("GUIDED")
    lat, lon = h.state.lat, h.state.lon
    h.command_int(M.MAV_CMD_DO_REPOSITION, -1, 0, 0, 0, round(lat * 1e7), round(lon * 1e7), -8)
    assert h.run(60, until=lambda: h.state.relative_alt_m < -7.5)
    h.mode("SURFACE")
    assert h.run(60, until=lambda: h.state.relative_alt_m > -0.05)


def test_a_tracker_in_auto_points_at_the_vehicle_it_hears(tmp_path):
    h = Harness(tmp_path, vehicle="tracker")
    h.arm()
    h.mode("AUTO")
    lat, lon = offset(h.state.lat, h.state.lon, -100, 0)  # due south
    h.send(M.MAVLink_global_position_int_message(0, round(lat * 1e7), round(lon * 1e7),
                                                 round((h.state.alt_amsl_m + 100) * 1000), 100000, 0, 0, 0, 0),
           sysid=5, compid=1)
    h.run(10)
    assert h.state.heading_deg == pytest.approx(180.0, abs=1.0)


def test_high_latency_links_are_silent_until_control_high_latency(tmp_path):
    h = Harness(tmp_path, config={"channels": [{"name": "sat", "type": "udp-server", "address": "127.0.0.1:0",
                                                "options": ["high_latency"]}]})
    h.run(6)
    assert h.received == [] and h.channel.stats.muted > 0
    assert h.command(M.MAV_CMD_CONTROL_HIGH_LATENCY, 1) == ACCEPTED
    h.run(10.5)
    kinds = {m.get_type() for m in h.received}
    assert "HIGH_LATENCY2" in kinds and "HEARTBEAT" not in kinds and "ATTITUDE" not in kinds
    assert len(h.of_type("HIGH_LATENCY2")) == 2
    assert h.command(M.MAV_CMD_CONTROL_HIGH_LATENCY, 2) == FAILED


def test_do_jump_tag_continues_the_mission_from_its_tag(tmp_path):
    h = flying(tmp_path)
    plan(h, wp(h, 30, 0), MissionItem(M.MAV_CMD_JUMP_TAG, param1=7), wp(h, 0, 10))
    h.mode("AUTO")
    h.run(1.0)
    assert h.node.plans.current_message().seq == 1
    assert h.command(M.MAV_CMD_DO_JUMP_TAG, 7) == ACCEPTED
    assert h.command(M.MAV_CMD_DO_JUMP_TAG, 8) == FAILED
    assert h.run(60, until=lambda: 3 in reached(h))
    assert reached(h) == [3]  # item 1 was skipped


def test_fixed_mag_cal_yaw_saves_offsets_that_pass_the_compass_check(tmp_path):
    h = Harness(tmp_path)
    h.set_param("COMPASS_OFS_X", 2500.0)
    assert h.command(M.MAV_CMD_FIXED_MAG_CAL_YAW, 90) == ACCEPTED
    assert abs(h.node.params.get("COMPASS_OFS_X")) < 100
    assert h.arm() == ACCEPTED


# --- jump loops (issue 17, item 6): bounded work per step, AP_Mission's jump limits -------------

def test_a_jump_loop_over_an_instant_nav_item_completes_one_item_per_step_and_keeps_flying(tmp_path):
    h = Harness(tmp_path)
    plan(h, MissionItem(M.MAV_CMD_NAV_TAKEOFF, REL, z=10), MissionItem(M.MAV_CMD_NAV_DELAY, param1=0),
         MissionItem(M.MAV_CMD_DO_JUMP, param1=2, param2=-1))
    h.arm()
    assert h.mode("AUTO") == ACCEPTED
    assert h.run(60, until=lambda: 1 in reached(h))
    mark = h.mark()
    h.run(10.0)  # 200 steps of 50 ms
    loops = [m.seq for m in h.of_type("MISSION_ITEM_REACHED", mark)]
    assert 100 <= len(loops) <= 200 and set(loops) == {2}, "one completion per step, never a burst"
    assert h.node.errors.snapshot() == {}
    assert h.state.armed and abs(h.state.relative_alt_m - 10) < 1.0, "holding at the takeoff altitude"
    assert h.node.plans.current_message().seq == 2


def test_instant_nav_items_in_a_finite_loop_take_turns_as_current_then_the_mission_goes_on(tmp_path):
    h = flying(tmp_path)
    plan(h, MissionItem(M.MAV_CMD_NAV_DELAY, param1=0), MissionItem(M.MAV_CMD_NAV_DELAY, param1=0),
         MissionItem(M.MAV_CMD_DO_JUMP, param1=1, param2=3), wp(h, 10, 0))
    h.mode("AUTO")
    mark = h.mark()
    assert h.run(60, until=lambda: 4 in reached(h))
    assert reached(h) == [1, 2] * 4 + [4]
    assert [m.seq for m in h.of_type("MISSION_CURRENT", mark)][-1] == 4
    assert h.node.errors.snapshot() == {}


@pytest.mark.parametrize("loop", [
    [MissionItem(M.MAV_CMD_DO_JUMP, param1=2, param2=-1)],  # a jump to itself, forever
    [MissionItem(M.MAV_CMD_DO_JUMP, param1=3, param2=-1), MissionItem(M.MAV_CMD_DO_JUMP, param1=2, param2=-1)],
    [MissionItem(M.MAV_CMD_DO_JUMP, param1=2, param2=100)],  # more than 64 jumps in one search
])
def test_a_jump_loop_with_no_nav_item_ends_the_mission_as_ardupilots_does(tmp_path, loop):
    h = Harness(tmp_path)
    plan(h, MissionItem(M.MAV_CMD_NAV_TAKEOFF, REL, z=10), *loop, wp(h, 10, 0))
    h.arm()
    h.mode("AUTO")
    assert h.run(60, until=lambda: 1 in reached(h)), "the takeoff (the control: the mission ran)"
    h.run(2.0)
    assert reached(h) == [1], "the waypoint after the loop is never reached"
    assert h.node.errors.snapshot() == {}
    assert h.state.armed and abs(h.state.relative_alt_m - 10) < 1.0


def test_a_finite_jump_within_the_limit_is_followed_to_the_end(tmp_path):
    h = Harness(tmp_path)
    plan(h, MissionItem(M.MAV_CMD_NAV_TAKEOFF, REL, z=10), MissionItem(M.MAV_CMD_DO_JUMP, param1=2, param2=60),
         wp(h, 10, 0))
    h.arm()
    h.mode("AUTO")
    assert h.run(60, until=lambda: 3 in reached(h))
    assert reached(h) == [1, 3]
