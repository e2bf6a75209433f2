"""RC parameters act as in ArduPilot (gcsd.vehicle.types.rc): each test changes a parameter and
watches the vehicle: the flight-mode switch (FLTMODE_CH, FLTMODE1..6 with ArduPilot's PWM
bands, 200 ms debounce), stick mapping (RCMAP_*), calibration (RCn_TRIM/_DZ/_MIN/_MAX/
_REVERSED) and the RC failsafe (FS_THR_ENABLE / FS_THR_VALUE) when overrides lapse."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M
from test_autopilot import flying
from vehicle_harness import Harness

from gcsd.vehicle.types.rc import scaled, switch_position

IGNORE = 65535


def override(h: Harness, **channels: int) -> None:
    values = [IGNORE] * 18
    for key, pwm in channels.items():
        values[int(key[2:]) - 1] = pwm
    h.send(M.MAVLink_rc_channels_override_message(1, 1, *values))


def mode(h: Harness) -> str:
    return h.node.vehicle.mode_name(h.state.mode)


@pytest.mark.parametrize("pwm, position", [
    (901, 0), (1230, 0), (1231, 1), (1360, 1), (1361, 2), (1490, 2), (1491, 3), (1620, 3), (1621, 4),
    (1749, 4), (1750, 5), (2199, 5), (900, None), (2200, None),
])
def test_mode_switch_bands_are_ardupilots(pwm, position):
    assert switch_position(pwm) == position


def test_the_flight_mode_channel_selects_fltmode_n_after_the_debounce(tmp_path):
    h = Harness(tmp_path)
    h.set_param("FLTMODE6", 2)  # ALT_HOLD
    h.set_param("FLTMODE1", 16)  # POSHOLD
    assert mode(h) == "STABILIZE"
    override(h, ch5=1900)  # FLTMODE_CH 5, position 6
    h.run(0.1)
    assert mode(h) == "STABILIZE"  # not yet: a new position holds 200 ms first
    h.run(0.3)
    assert mode(h) == "ALT_HOLD"
    override(h, ch5=1100)
    h.run(0.5)
    assert mode(h) == "POSHOLD"
    h.set_param("FLTMODE1", 5)  # the table is read when the switch moves, not when it is written
    h.run(0.5)
    assert mode(h) == "POSHOLD"


def test_fltmode_ch_moves_the_switch_to_another_channel(tmp_path):
    h = Harness(tmp_path)
    h.set_param("FLTMODE_CH", 7)
    h.set_param("FLTMODE6", 2)
    override(h, ch5=1900)
    h.run(0.5)
    assert mode(h) == "STABILIZE"  # channel 5 is no longer the switch
    override(h, ch5=1900, ch7=1900)
    h.run(0.5)
    assert mode(h) == "ALT_HOLD"


def test_a_switch_position_the_vehicle_refuses_says_why(tmp_path):
    h = Harness(tmp_path)
    h.set_param("FLTMODE6", 3)  # AUTO without a mission
    mark = h.mark()
    override(h, ch5=1900)
    h.run(0.5)
    assert mode(h) == "STABILIZE"
    assert "Mode change to AUTO failed: no mission" in h.texts(mark)


def test_rover_reads_mode_ch_and_mode_n(tmp_path):
    h = Harness(tmp_path, vehicle="rover")
    h.set_param("MODE6", 4)  # HOLD
    override(h, ch8=1900)  # MODE_CH 8
    h.run(0.5)
    assert mode(h) == "HOLD"


def test_rcmap_pitch_moves_the_pitch_stick_to_another_channel(tmp_path):
    h = flying(tmp_path)
    h.mode("LOITER")
    h.set_param("FS_THR_ENABLE", 0)
    h.set_param("RCMAP_PITCH", 6)
    override(h, ch2=1200)  # no longer pitch
    h.run(2.0)
    assert h.state.groundspeed_ms < 0.3
    override(h, ch6=1200)
    h.run(2.0)
    assert h.state.groundspeed_ms > 1.0


def test_the_dead_zone_and_reversal_shape_the_stick(tmp_path):
    h = flying(tmp_path)
    h.mode("LOITER")
    h.set_param("FS_THR_ENABLE", 0)
    h.set_param("RC2_DZ", 200)
    override(h, ch2=1350)  # inside 1500 +- 200: centred
    h.run(2.0)
    assert h.state.groundspeed_ms < 0.3
    h.set_param("RC2_DZ", 20)
    override(h, ch2=1350)
    h.run(2.0)
    assert h.state.groundspeed_ms > 0.5
    params = h.node.params.get
    assert scaled(params, 2, 1350) == pytest.approx((1350 - 1480) / (1480 - 1000))  # TRIM - DZ to MIN
    assert scaled(params, 2, 1000) == -1.0 and scaled(params, 2, 2000) == 1.0
    h.set_param("RC2_REVERSED", 1)
    assert scaled(h.node.params.get, 2, 1000) == 1.0
    h.set_param("RC2_MIN", 1200)
    assert scaled(h.node.params.get, 2, 1200) == 1.0


def test_overrides_that_lapse_are_rc_loss_and_the_throttle_failsafe_returns(tmp_path):
    h = flying(tmp_path)
    h.mode("LOITER")
    override(h, ch1=1500)
    mark = h.mark()
    h.run(4.0)  # RC_OVERRIDE_TIME 3 s
    assert "Radio Failsafe" in h.texts(mark)
    assert mode(h) == "RTL"  # FS_THR_ENABLE 1
    assert h.state.failsafe == "Radio"
    override(h, ch1=1500)
    h.run(0.2)
    assert "Radio Failsafe Cleared" in h.texts(mark)


def test_fs_thr_enable_chooses_the_action_and_0_disables_it(tmp_path):
    h = flying(tmp_path)
    h.set_param("FS_THR_ENABLE", 3)  # always LAND
    h.mode("LOITER")
    override(h, ch1=1500)
    h.run(4.0)
    assert mode(h) == "LAND"

    h2 = flying(tmp_path / "b")
    h2.set_param("FS_THR_ENABLE", 0)
    h2.mode("LOITER")
    override(h2, ch1=1500)
    mark = h2.mark()
    h2.run(4.0)
    assert mode(h2) == "LOITER" and "Radio Failsafe" not in h2.texts(mark)


def test_throttle_below_fs_thr_value_is_rc_loss(tmp_path):
    h = flying(tmp_path)
    h.mode("LOITER")
    mark = h.mark()
    override(h, ch3=1000)  # above FS_THR_VALUE 975: a low stick, not a failsafe
    h.run(0.5)
    assert "Radio Failsafe" not in h.texts(mark)
    h.set_param("FS_THR_VALUE", 1050)
    override(h, ch3=1000)
    h.run(0.5)
    assert "Radio Failsafe" in h.texts(mark)
    assert mode(h) == "RTL"


def test_rc_loss_on_the_ground_disarms(tmp_path):
    h = Harness(tmp_path)
    assert h.arm() == M.MAV_RESULT_ACCEPTED
    override(h, ch1=1500)
    mark = h.mark()
    h.run(4.0)
    assert "Radio Failsafe" in h.texts(mark)
    assert not h.state.armed


def test_manual_control_drives_the_channels_rcmap_names(tmp_path):
    h = flying(tmp_path)
    h.mode("LOITER")
    h.set_param("FS_THR_ENABLE", 0)
    h.set_param("RCMAP_PITCH", 6)
    h.send(M.MAVLink_manual_control_message(1, 600, 0, 500, 0, 0))  # x: forward
    h.run(0.1)
    assert h.state.rc_override[6] < 1500 and 2 not in h.state.rc_override
    h.run(1.5)
    assert h.state.groundspeed_ms > 0.5


def test_rudder_right_with_throttle_down_arms_after_two_seconds_and_left_disarms(tmp_path):
    h = Harness(tmp_path)
    h.set_param("FS_THR_ENABLE", 0)
    override(h, ch3=1000, ch4=2000)  # throttle at RC3_MIN, yaw full right
    h.run(1.5)
    assert not h.state.armed  # not yet: the gesture is held 2 s
    override(h, ch3=1000, ch4=2000)
    h.run(1.0)
    assert h.state.armed
    override(h, ch3=1000, ch4=1000)  # full left, on the ground
    h.run(2.5)
    assert not h.state.armed


def test_arming_rudder_0_disables_the_gesture_and_1_only_arms(tmp_path):
    h = Harness(tmp_path)
    h.set_param("FS_THR_ENABLE", 0)
    h.set_param("ARMING_RUDDER", 0)
    override(h, ch3=1000, ch4=2000)
    h.run(2.5)
    assert not h.state.armed
    h.set_param("ARMING_RUDDER", 1)
    override(h, ch3=1000, ch4=2000)
    h.run(2.5)
    assert h.state.armed
    override(h, ch3=1000, ch4=1000)
    h.run(2.5)
    assert h.state.armed  # 1: arming only


def test_rudder_arming_runs_the_pre_arm_checks(tmp_path):
    h = Harness(tmp_path)
    h.set_param("FS_THR_ENABLE", 0)
    h.set_param("RC1_MIN", 1400)  # pre-arm: RC1_MIN too high
    mark = h.mark()
    override(h, ch3=1000, ch4=2000)
    h.run(2.5)
    assert not h.state.armed and "PreArm: RC1_MIN too high" in h.texts(mark)


def test_the_throttle_stick_climbs_at_pilot_speed_up_and_descends_at_pilot_speed_dn(tmp_path):
    h = flying(tmp_path, alt=20.0)
    h.mode("ALT_HOLD")
    h.set_param("FS_THR_ENABLE", 0)
    override(h, ch3=2000)  # full up
    h.run(2.0)
    assert -h.state.vd_ms == pytest.approx(2.5, abs=0.1)  # PILOT_SPEED_UP 250 cm/s
    h.set_param("PILOT_SPEED_UP", 100)
    override(h, ch3=2000)
    h.run(2.0)
    assert -h.state.vd_ms == pytest.approx(1.0, abs=0.1)
    override(h, ch3=1000)  # full down: PILOT_SPEED_DN 0 means PILOT_SPEED_UP
    h.run(2.0)
    assert h.state.vd_ms == pytest.approx(1.0, abs=0.1)
    h.set_param("PILOT_SPEED_DN", 150)
    override(h, ch3=1000)
    h.run(2.0)
    assert h.state.vd_ms == pytest.approx(1.5, abs=0.1)


def test_land_descends_at_land_speed_high_above_land_alt_low(tmp_path):
    h = flying(tmp_path, alt=30.0)
    h.mode("LAND")
    h.run(2.0)
    assert h.state.vd_ms == pytest.approx(1.5, abs=0.1)  # LAND_SPEED_HIGH 0: WPNAV_SPEED_DN 150 cm/s
    h.set_param("LAND_SPEED_HIGH", 300)
    h.run(1.0)
    assert h.state.vd_ms == pytest.approx(3.0, abs=0.1)
    h.run(30.0, until=lambda: h.state.relative_alt_m < 8.0)
    h.run(1.0)
    assert h.state.vd_ms == pytest.approx(0.5, abs=0.05)  # below LAND_ALT_LOW 10 m: LAND_SPEED 50 cm/s


def _fly_east(h: Harness) -> float:
    from gcsd.vehicle.sim.geo import offset
    s = h.state
    lat, lon = offset(s.lat, s.lon, 0.0, 80.0)
    h.node.autopilot.goto(lat, lon, s.alt_amsl_m)
    h.run(6.0)
    return h.state.heading_deg


def test_wp_yaw_behavior_0_keeps_the_heading_and_1_faces_the_way(tmp_path):
    h = flying(tmp_path)
    h.set_param("WP_YAW_BEHAVIOR", 0)
    before = h.state.heading_deg
    assert _fly_east(h) == pytest.approx(before, abs=1.0)
    h2 = flying(tmp_path / "b")
    h2.set_param("WP_YAW_BEHAVIOR", 1)
    assert _fly_east(h2) == pytest.approx(90.0, abs=10.0)
