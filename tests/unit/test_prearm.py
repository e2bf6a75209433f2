"""Pre-arm checks: each one made to fail refuses arming (COMMAND_ACK FAILED) with its
"PreArm: ..." STATUSTEXT; a forced arm (21196) skips them; ARMING_CHECK 0 disables them;
RUN_PREARM_CHECKS reports them without arming."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M
from vehicle_harness import Harness

from gcsd.vehicle.mission import MissionItem
from gcsd.vehicle.sim.geo import offset
from gcsd.vehicle.types.prearm import PrearmDisplay

FAILED, ACCEPTED = M.MAV_RESULT_FAILED, M.MAV_RESULT_ACCEPTED


def _far_circle(h: Harness) -> None:
    s = h.state
    lat, lon = offset(s.home_lat, s.home_lon, 500.0, 0.0)
    h.node.plans.fence.replace((MissionItem(M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_FRAME_GLOBAL, param1=50.0,
                                              x=round(lat * 1e7), y=round(lon * 1e7)),))


CHECKS = [
    ("angle_max", {}, lambda h: _own_write(h, "ANGLE_MAX", 9000), "PreArm: Check ANGLE_MAX"),
    ("gps_fix", {"SIM_GPS_DISABLE": 1}, None, "PreArm: Need 3D Fix"),
    ("gps_hdop", {"SIM_GPS_HDOP": 3.0}, None, "PreArm: High GPS HDOP"),
    ("battery_voltage", {"BATT_ARM_VOLT": 20.0}, None, "PreArm: Battery below minimum arming voltage"),
    ("battery_capacity", {"BATT_ARM_MAH": 6000}, None, "PreArm: Battery below minimum arming capacity"),
    ("battery_low_failsafe", {"BATT_LOW_VOLT": 17.0}, None, "PreArm: Battery 1 low voltage failsafe"),
    ("rc_min", {"RC1_MIN": 1400}, None, "PreArm: RC1_MIN too high"),
    ("rc_max", {"RC2_MAX": 1600}, None, "PreArm: RC2_MAX too low"),
    ("rc_trim", {"RC4_TRIM": 2100}, None, "PreArm: RC4_TRIM out of range"),  # RC4_MAX is 2000
    ("compass", {}, lambda h: _own_write(h, "COMPASS_OFS_X", 2000.0), "PreArm: Compass offsets too high"),
    ("fence_outside", {"FENCE_ENABLE": 1, "FENCE_TYPE": 4}, _far_circle, "PreArm: Fence: vehicle outside the polygon fence"),
    ("fence_no_position", {"FENCE_ENABLE": 1, "SIM_GPS_DISABLE": 1}, None, "PreArm: Fence requires position"),
]


def _own_write(h: Harness, name: str, value: float) -> None:
    """A value no ground station can write (outside ArduPilot's documented range: ANGLE_MAX
    1000..8000, COMPASS_OFS_X -400..400) but gcsd itself can: a compass calibration's result,
    a saved file. The check must still catch it."""
    assert h.node.params.set(name, value, force=True).value == "changed"


def _break(h: Harness, params: dict, setup) -> None:
    for name, value in params.items():
        h.set_param(name, value)
    if setup is not None:
        setup(h)
    h.run(0.2)  # the simulation picks up SIM_ changes


@pytest.mark.parametrize("name, params, setup, text", CHECKS, ids=[c[0] for c in CHECKS])
def test_a_failing_prearm_check_refuses_arming_with_its_statustext(tmp_path, name, params, setup, text):
    h = Harness(tmp_path)
    _break(h, params, setup)
    mark = h.mark()
    assert h.arm() == FAILED
    assert any(t.startswith(text) for t in h.texts(mark)), h.texts(mark)
    h.run(1.1)
    assert not h.state.armed
    assert not h.of_type("HEARTBEAT", mark)[-1].base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED


@pytest.mark.parametrize("name, params, setup, text", CHECKS[:3], ids=[c[0] for c in CHECKS[:3]])
def test_a_forced_arm_skips_the_failing_check(tmp_path, name, params, setup, text):
    h = Harness(tmp_path)
    _break(h, params, setup)
    mark = h.mark()
    assert h.arm(force=True) == ACCEPTED
    assert h.state.armed
    assert not any(t.startswith("PreArm") for t in h.texts(mark))


def test_arming_check_zero_disables_the_checks(tmp_path):
    h = Harness(tmp_path)
    _break(h, {"RC1_MIN": 1400, "ARMING_CHECK": 0}, None)
    assert h.arm() == ACCEPTED


def test_arming_check_bitmask_selects_checks(tmp_path):
    h = Harness(tmp_path)
    _break(h, {"RC1_MIN": 1400, "ARMING_CHECK": 8}, None)  # GPS only: the RC check is skipped
    assert h.arm() == ACCEPTED


def test_every_failing_check_is_reported_not_just_the_first(tmp_path):
    h = Harness(tmp_path)
    _break(h, {"RC1_MIN": 1400}, lambda h: _own_write(h, "COMPASS_OFS_Y", -3000.0))
    mark = h.mark()
    assert h.arm() == FAILED
    assert {"PreArm: RC1_MIN too high", "PreArm: Compass offsets too high"} <= set(h.texts(mark))


def test_run_prearm_checks_reports_failures_without_arming(tmp_path):
    h = Harness(tmp_path)
    _break(h, {}, lambda h: _own_write(h, "ANGLE_MAX", 500))
    mark = h.mark()
    assert h.command(M.MAV_CMD_RUN_PREARM_CHECKS) == ACCEPTED
    assert "PreArm: Check ANGLE_MAX" in h.texts(mark)
    assert not h.state.armed


def test_a_mode_that_is_not_armable_refuses_arming(tmp_path):
    h = Harness(tmp_path)
    h.mode("BRAKE")
    mark = h.mark()
    assert h.arm() == FAILED
    assert "Arm: Mode not armable" in h.texts(mark)


def test_a_companion_computer_has_nothing_to_arm(tmp_path):
    h = Harness(tmp_path, vehicle="companion")
    assert h.arm() == M.MAV_RESULT_UNSUPPORTED


def test_the_prearm_display_asks_for_no_send_pass_while_armed():
    display = PrearmDisplay()
    assert display.poll(100.0, False, lambda: ["Check ANGLE_MAX"]) == ["PreArm: Check ANGLE_MAX"]
    for now in (100.5, 101.0, 150.0):
        assert display.poll(now, True, lambda: ["never asked"]) == []
        assert display.next_deadline() > now, "a deadline in the past would make the send pass spin"
    assert display.poll(151.0, False, lambda: ["Check ANGLE_MAX"]) == ["PreArm: Check ANGLE_MAX"], "disarmed again"
