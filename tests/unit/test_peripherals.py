"""Payload and per-vehicle commands that act on state (services.peripherals, vehicles.commands),
through the real node with a float clock."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M
from vehicle_harness import Harness

ACCEPTED, DENIED, FAILED, UNSUPPORTED = (
    M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_DENIED, M.MAV_RESULT_FAILED, M.MAV_RESULT_UNSUPPORTED)


def test_the_safety_switch_blocks_arming_until_turned_off(tmp_path):
    h = Harness(tmp_path)
    assert h.command(M.MAV_CMD_DO_SET_SAFETY_SWITCH_STATE, M.SAFETY_SWITCH_STATE_SAFE) == ACCEPTED
    mark = h.mark()
    assert h.arm() == FAILED
    assert "PreArm: Hardware safety switch" in h.texts(mark)
    assert h.command(M.MAV_CMD_DO_SET_SAFETY_SWITCH_STATE, M.SAFETY_SWITCH_STATE_DANGEROUS) == ACCEPTED
    assert h.arm() == ACCEPTED
    assert h.command(M.MAV_CMD_DO_SET_SAFETY_SWITCH_STATE, M.SAFETY_SWITCH_STATE_SAFE) == DENIED  # armed


def test_the_gripper_needs_grip_enable_and_then_grabs_and_releases(tmp_path):
    h = Harness(tmp_path)
    assert h.command(M.MAV_CMD_DO_GRIPPER, 1, M.GRIPPER_ACTION_GRAB) == FAILED  # GRIP_ENABLE 0
    h.set_param("GRIP_ENABLE", 1)
    mark = h.mark()
    assert h.command(M.MAV_CMD_DO_GRIPPER, 1, M.GRIPPER_ACTION_GRAB) == ACCEPTED
    assert h.command(M.MAV_CMD_DO_GRIPPER, 1, M.GRIPPER_ACTION_RELEASE) == ACCEPTED
    assert h.command(M.MAV_CMD_DO_GRIPPER, 1, 7) == FAILED
    h.run(1)
    assert h.texts(mark)[:2] == ["Gripper load grabbing", "Gripper load releasing"]


def test_a_parachute_release_stops_the_motors_only_when_enabled_and_flying(tmp_path):
    h = Harness(tmp_path)
    mark = h.mark()
    assert h.command(M.MAV_CMD_DO_PARACHUTE, M.PARACHUTE_RELEASE) == ACCEPTED
    h.run(0.5)
    assert "Parachute: Not enabled" in h.texts(mark)
    assert h.command(M.MAV_CMD_DO_PARACHUTE, M.PARACHUTE_ENABLE) == ACCEPTED
    assert h.node.params.get("CHUTE_ENABLED") == 1
    h.mode("GUIDED")
    assert h.arm() == ACCEPTED
    assert h.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10) == ACCEPTED
    assert h.run(30, until=lambda: h.state.relative_alt_m > 5)
    assert h.command(M.MAV_CMD_DO_PARACHUTE, M.PARACHUTE_RELEASE) == ACCEPTED
    assert not h.state.armed


def test_battery_reset_sets_the_remaining_charge(tmp_path):
    h = Harness(tmp_path)
    assert h.command(M.MAV_CMD_BATTERY_RESET, 1, 40) == ACCEPTED
    assert h.state.battery_remaining_pct == 40
    assert h.command(M.MAV_CMD_BATTERY_RESET, 0, 90) == ACCEPTED  # no battery in the mask: nothing
    assert h.state.battery_remaining_pct == 40
    assert h.command(M.MAV_CMD_BATTERY_RESET, 1, 140) == FAILED


@pytest.mark.parametrize("function, position, mode, result", [
    (4, 2, "RTL", ACCEPTED),  # RTL high
    (56, 2, "LOITER", ACCEPTED),
    (56, 0, "STABILIZE", ACCEPTED),  # low: nothing to fall back to
    (51, 2, "STABILIZE", FAILED),  # MANUAL: a copter has no such mode
    (999, 2, "STABILIZE", FAILED),  # "Invalid channel option"
    (4, 3, "STABILIZE", FAILED),  # no such switch position
])
def test_aux_functions_switch_modes(tmp_path, function, position, mode, result):
    h = Harness(tmp_path)
    assert h.command(M.MAV_CMD_DO_AUX_FUNCTION, function, position) == result
    assert h.node.vehicle.mode_name(h.state.mode) == mode


def test_aux_arm_disarm_and_fence(tmp_path):
    h = Harness(tmp_path)
    assert h.command(M.MAV_CMD_DO_AUX_FUNCTION, 153, 2) == ACCEPTED and h.state.armed
    assert h.command(M.MAV_CMD_DO_AUX_FUNCTION, 153, 0) == ACCEPTED and not h.state.armed
    assert h.command(M.MAV_CMD_DO_AUX_FUNCTION, 11, 2) == ACCEPTED
    assert h.node.params.get("FENCE_ENABLE") == 1


def test_per_vehicle_answers_win_over_the_generic_ones(tmp_path):
    copter = Harness(tmp_path / "c")
    assert copter.command(M.MAV_CMD_CONDITION_YAW, 90) == ACCEPTED  # any mode, on a copter
    assert copter.command(M.MAV_CMD_AIRFRAME_CONFIGURATION, 0, 1) == ACCEPTED  # landing gear retract
    rover = Harness(tmp_path / "r", vehicle="rover")
    assert rover.command(M.MAV_CMD_CONDITION_YAW, 90) == UNSUPPORTED
    assert rover.command(M.MAV_CMD_AIRFRAME_CONFIGURATION, 0, 1) == UNSUPPORTED  # no landing gear
    plane = Harness(tmp_path / "p", vehicle="plane")
    assert plane.command(M.MAV_CMD_DO_VTOL_TRANSITION, 4) == FAILED  # not a quadplane
    assert plane.command(M.MAV_CMD_GUIDED_CHANGE_SPEED, 0, 20) == FAILED  # not in GUIDED


def test_motor_test_refused_with_arducopters_reasons(tmp_path):
    h = Harness(tmp_path)
    h.set_param("RC1_MIN", 1400)  # RC not calibrated
    mark = h.mark()
    assert h.command(M.MAV_CMD_DO_MOTOR_TEST, 1, M.MOTOR_TEST_THROTTLE_PERCENT, 10, 1) == FAILED
    assert h.command(M.MAV_CMD_DO_MOTOR_TEST, 1, M.MOTOR_TEST_THROTTLE_PWM, 1300, 1) == ACCEPTED  # PWM skips it
    h.run(0.5)
    assert "Motor Test: RC not calibrated" in h.texts(mark)
    assert h.command(M.MAV_CMD_DO_MOTOR_TEST, 9, M.MOTOR_TEST_THROTTLE_PERCENT, 10, 1) == FAILED  # a quad has 4


def test_available_modes_one_index_or_all_after_the_ack(tmp_path):
    h = Harness(tmp_path, vehicle="rover")
    count = len(h.node.vehicle.modes)
    mark = h.mark()
    assert h.command(M.MAV_CMD_REQUEST_MESSAGE, 435, 0) == ACCEPTED  # every mode
    h.run(0.2)
    got = [m for m in h.received[mark:] if m.get_type() == "UNKNOWN_435"]
    assert len(got) == count
    types = [m.get_type() for m in h.received[mark:]]
    assert types.index("COMMAND_ACK") < types.index("UNKNOWN_435")  # the ACK first, as QGC expects
    assert h.command(M.MAV_CMD_REQUEST_MESSAGE, 435, count + 1) == DENIED
    assert h.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == ACCEPTED  # others go on
