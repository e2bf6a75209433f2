"""Frame, motor and battery parameters act as in ArduPilot: each test changes a parameter and
reads what a ground station reads. FRAME_CLASS / FRAME_TYPE: how many outputs of
SERVO_OUTPUT_RAW drive motors and the banner's frame line; MOT_PWM_MIN/MAX and
MOT_SPIN_ARM/MIN/MAX: the motor PWM disarmed, armed at idle and in flight (vehicles/motors.py);
BATT_MONITOR 0: no BATTERY_STATUS, no battery in SYS_STATUS, no battery failsafe."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as M
from test_autopilot import flying
from vehicle_harness import Harness

from gcsd.vehicle.types.motors import rover_throttle_pwm

ACCEPTED = M.MAV_RESULT_ACCEPTED


def request(h: Harness, msgid: int, name: str):
    mark = h.mark()
    result = h.command(M.MAV_CMD_REQUEST_MESSAGE, msgid)
    h.run(0.05)
    got = h.of_type(name, mark)
    return result, (got[-1] if got else None)


def outputs(h: Harness) -> list[int]:
    _, msg = request(h, M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, "SERVO_OUTPUT_RAW")
    return [getattr(msg, f"servo{n}_raw") for n in range(1, 17)]


def test_frame_class_sets_how_many_outputs_drive_motors(tmp_path):
    h = Harness(tmp_path)
    assert outputs(h)[:6] == [1000, 1000, 1000, 1000, 0, 0]  # quad, disarmed: MOT_PWM_MIN
    h.set_param("FRAME_CLASS", 2)  # hexa: outputs 5 and 6 become motors 5 and 6
    assert outputs(h)[:7] == [1000] * 6 + [0]
    h.set_param("FRAME_CLASS", 7)  # tri: motor 4's output is not used by the frame
    assert outputs(h)[:5] == [1000, 1000, 1000, 0, 0]


def test_motor_pwm_follows_mot_pwm_and_mot_spin(tmp_path):
    h = Harness(tmp_path)
    assert h.arm() == ACCEPTED
    assert outputs(h)[:4] == [1100] * 4  # MOT_SPIN_ARM 0.1 of 1000..2000
    h.set_param("MOT_SPIN_ARM", 0.2)
    assert outputs(h)[:4] == [1200] * 4
    h.set_param("MOT_PWM_MIN", 1100)
    h.set_param("MOT_PWM_MAX", 1900)
    assert outputs(h)[:4] == [1260] * 4  # 1100 + 0.2 x 800
    h.set_param("MOT_PWM_MIN", 0)  # 0: the throttle channel's range, RC3_MIN..RC3_MAX
    assert outputs(h)[:4] == [1200] * 4


def test_motors_in_flight_stay_between_mot_spin_min_and_max(tmp_path):
    h = flying(tmp_path)
    lo, hi = 1000 + 1000 * 0.15, 1000 + 1000 * 0.95
    pwm = outputs(h)[:4]
    assert all(lo <= p <= hi for p in pwm) and len(set(pwm)) == 1, pwm
    h.set_param("MOT_SPIN_MIN", 0.25)
    assert all(p >= 1250 for p in outputs(h)[:4])


def test_the_banner_names_the_frame(tmp_path):
    h = Harness(tmp_path)
    mark = h.mark()
    assert h.command(M.MAV_CMD_DO_SEND_BANNER) == ACCEPTED
    h.run(0.1)
    assert h.texts(mark)[:2] == ["ArduCopter V4.6.3 (3fc7011a)", "Frame: QUAD/PLUS"]
    h.set_param("FRAME_CLASS", 2)
    h.set_param("FRAME_TYPE", 1)
    mark = h.mark()
    h.command(M.MAV_CMD_DO_SEND_BANNER)
    h.run(0.1)
    assert "Frame: HEXA/X" in h.texts(mark)


def test_batt_monitor_0_means_no_battery_telemetry_and_no_battery_failsafe(tmp_path):
    h = Harness(tmp_path)
    result, msg = request(h, M.MAVLINK_MSG_ID_BATTERY_STATUS, "BATTERY_STATUS")
    assert result == ACCEPTED and msg is not None  # positive control: a monitored battery
    _, status = request(h, M.MAVLINK_MSG_ID_SYS_STATUS, "SYS_STATUS")
    assert status.voltage_battery > 0 and status.battery_remaining > 0
    h.set_param("BATT_MONITOR", 0)
    result, msg = request(h, M.MAVLINK_MSG_ID_BATTERY_STATUS, "BATTERY_STATUS")
    assert msg is None
    _, status = request(h, M.MAVLINK_MSG_ID_SYS_STATUS, "SYS_STATUS")
    assert (status.voltage_battery, status.current_battery, status.battery_remaining) == (0, -1, -1)
    assert not status.onboard_control_sensors_present & M.MAV_SYS_STATUS_SENSOR_BATTERY


def test_battery_failsafe_needs_a_battery_monitor(tmp_path):
    h = flying(tmp_path)
    h.set_param("BATT_FS_LOW_ACT", 2)  # RTL
    h.set_param("BATT_MONITOR", 0)
    h.set_param("BATT_LOW_MAH", 3290)  # 3300 mAh pack: low almost at once, if it were monitored
    mark = h.mark()
    h.run(3)
    assert not [t for t in h.texts(mark) if t.startswith("Battery 1 is low")]
    h.set_param("BATT_MONITOR", 4)
    h.run(3)
    assert [t for t in h.texts(mark) if t.startswith("Battery 1 is low")]
    assert h.node.vehicle.mode_name(h.state.mode) == "RTL"


def test_a_planes_throttle_output_follows_the_throttle_from_servo_min(tmp_path):
    h = Harness(tmp_path, vehicle="plane")
    assert outputs(h)[2] == 1000  # SERVO3_FUNCTION 70 (throttle), disarmed: SERVO3_MIN
    assert outputs(h)[0] == 1500  # aileron at SERVO1_TRIM
    h.set_param("SERVO3_MIN", 1100)
    assert outputs(h)[2] == 1100
    h.set_param("SERVO3_FUNCTION", 0)  # no longer the throttle: nothing assigned
    assert outputs(h)[2] == 0


def test_a_rovers_throttle_output_rests_at_trim_and_drives_towards_max(tmp_path):
    h = Harness(tmp_path, vehicle="rover")
    assert outputs(h)[2] == 1500  # SERVO3 throttle: centred for reverse
    assert h.arm() == ACCEPTED
    h.node.state.throttle_pct = 50  # as the simulation sets it while driving
    assert rover_throttle_pwm(h.node, 3) == 1750  # 1500 + (2000 - 1500) x 0.5
    h.set_param("SERVO3_REVERSED", 1)
    assert rover_throttle_pwm(h.node, 3) == 1250


def test_a_low_voltage_must_last_batt_low_timer_seconds(tmp_path):
    h = flying(tmp_path)
    h.set_param("BATT_FS_LOW_ACT", 2)  # RTL
    volts = h.state.battery_voltage_v
    h.set_param("BATT_LOW_VOLT", round(volts + 1.0, 1))  # below it from now on
    mark = h.mark()
    h.run(8.0)
    assert not [t for t in h.texts(mark) if t.startswith("Battery 1 is low")]  # BATT_LOW_TIMER 10 s
    h.run(3.0)
    assert [t for t in h.texts(mark) if t.startswith("Battery 1 is low")]
    assert h.node.vehicle.mode_name(h.state.mode) == "RTL"


def test_batt_low_timer_0_acts_on_the_first_low_reading(tmp_path):
    h = flying(tmp_path)
    h.set_param("BATT_LOW_TIMER", 0)
    h.set_param("BATT_LOW_VOLT", round(h.state.battery_voltage_v + 1.0, 1))
    mark = h.mark()
    h.run(0.5)
    assert [t for t in h.texts(mark) if t.startswith("Battery 1 is low")]
