"""The calibration dialogues as QGroundControl's Sensors page drives them (APMSensorsComponentController),
against the real daemon over UDP with pymavlink: each result lands in ArduPilot's parameter names.

- Compass: DO_CANCEL_MAG_CAL (QGC's probe for onboard calibration) -> COMPASS_CAL_FIT 100 ->
  DO_START_MAG_CAL(mask, 0, autosave 1)
  -> MAG_CAL_PROGRESS ... -> MAG_CAL_REPORT per compass -> COMPASS_OFS* read back.
- Accelerometer: PREFLIGHT_CALIBRATION param5 1 -> ACCELCAL_VEHICLE_POS 1..6 from the vehicle, each
  answered by a COMMAND_ACK (QGC's Next button) -> ACCELCAL_VEHICLE_POS_SUCCESS.
- Level (param5 2), simple accelerometer (param5 4), pressure (param3 1): IN_PROGRESS, then ACCEPTED,
  AHRS_TRIM_* / INS_ACC* / BARO1_GND_PRESS set.
- Motor test (DO_MOTOR_TEST) and the radio calibration's RCn_ parameters.
The same dialogues with a float clock, and the other calibrations: tests/unit/test_calibration.py.
"""

from __future__ import annotations

import pytest

from .helpers import M, is_ack, wait_for

UDP = {"channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]}


@pytest.fixture
def gcs(daemon, client):
    d = daemon(UDP)
    c = client(f"udpout:127.0.0.1:{d.port('gcs')}")
    c.heartbeat()
    assert wait_for(c, lambda r: r.type == "HEARTBEAT" and r.src == (1, 1), 3.0)
    return c


def _ack(gcs, command: int, *params: float, timeout: float = 3.0):
    mark = gcs.mark()
    gcs.command_long(command, *params)
    r = wait_for(gcs, is_ack(command), timeout, since=mark)
    assert r is not None, f"no COMMAND_ACK for {command}"
    return r.msg.result


def _param(gcs, name: str):
    mark = gcs.mark()
    gcs.send(M.MAVLink_param_request_read_message(1, 1, name.encode(), -1))
    r = wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == name, 3.0, since=mark)
    return None if r is None else r.msg.param_value


def _texts(gcs, since: int) -> list[str]:
    return [r.msg.text for r in gcs.since(since, "STATUSTEXT")]


def test_compass_calibration_as_qgroundcontrol_runs_it_saves_offsets_and_the_daemon_lives(daemon, client):
    d = daemon({"channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"},
                             {"name": "gcs2", "type": "udp-server", "address": "127.0.0.1:0"}]})
    gcs = client(f"udpout:127.0.0.1:{d.port('gcs')}")
    other = client(f"udpout:127.0.0.1:{d.port('gcs2')}", sysid=254)  # a second ground station watching
    for c in (gcs, other):
        c.heartbeat()
        assert wait_for(c, lambda r: r.type == "HEARTBEAT" and r.src == (1, 1), 3.0)
    before = _param(gcs, "COMPASS_OFS_X")
    assert before is not None
    assert _ack(gcs, M.MAV_CMD_DO_CANCEL_MAG_CAL) == M.MAV_RESULT_ACCEPTED  # "onboard cal supported"
    fitness = _param(gcs, "COMPASS_CAL_FIT")
    # QGroundControl raises COMPASS_CAL_FIT to 100 for the calibration (and restores it afterwards).
    # ArduPilot takes any value; gcsd refuses it beyond the documented range 4..32 and answers with
    # the value it keeps (a difference owned by the parameter store, see the final report).
    mark = gcs.mark()
    gcs.send(M.MAVLink_param_set_message(1, 1, b"COMPASS_CAL_FIT", 100.0, M.MAV_PARAM_TYPE_REAL32))
    assert wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == "COMPASS_CAL_FIT", 3.0, since=mark)
    mark = gcs.mark()
    # QGC's mask: a bit for each compass with COMPASS_DEV_IDn > 0 and COMPASS_USEn set
    mask = sum(1 << i for i, n in enumerate(("", "2", "3"))
               if _param(gcs, f"COMPASS_DEV_ID{n}") > 0 and _param(gcs, f"COMPASS_USE{n}"))
    assert mask == 0b111  # ArduPilot SITL's three compasses
    assert _ack(gcs, M.MAV_CMD_DO_START_MAG_CAL, mask, 0, 1, 0, 0) == M.MAV_RESULT_ACCEPTED
    report = wait_for(gcs, lambda r: r.type == "MAG_CAL_REPORT", 10.0, since=mark)
    assert report is not None, "no MAG_CAL_REPORT"
    # QGC finishes only when every compass of its mask has reported
    assert wait_for(gcs, lambda r: r.type == "MAG_CAL_REPORT" and r.msg.compass_id == 2, 3.0, since=mark)
    assert {r.msg.compass_id for r in gcs.since(mark, "MAG_CAL_REPORT")} == {0, 1, 2}
    progress = gcs.since(mark, "MAG_CAL_PROGRESS")
    assert progress, "no MAG_CAL_PROGRESS before the report"
    pcts = [r.msg.completion_pct for r in progress if r.msg.compass_id == 0]
    assert pcts == sorted(pcts) and pcts[-1] < 100
    assert {r.msg.cal_status for r in progress} <= {M.MAG_CAL_RUNNING_STEP_ONE, M.MAG_CAL_RUNNING_STEP_TWO}
    assert progress[0].msg.cal_mask & 1 and progress[0].msg.attempt == 1
    rep = report.msg
    assert (rep.cal_status, rep.autosaved) == (M.MAG_CAL_SUCCESS, 1)
    assert 0 < rep.fitness < 16.0  # below COMPASS_CAL_FIT's default: QGroundControl calls it a success
    saved = [_param(gcs, f"COMPASS_OFS_{a}") for a in "XYZ"]
    assert saved == pytest.approx([rep.ofs_x, rep.ofs_y, rep.ofs_z])
    assert (rep.diag_x, rep.diag_y, rep.diag_z) != (0.0, 0.0, 0.0)
    gcs.send(M.MAVLink_param_set_message(1, 1, b"COMPASS_CAL_FIT", fitness, M.MAV_PARAM_TYPE_REAL32))
    # the other ground station saw it too (ArduPilot sends them to every GCS link)
    seen = wait_for(other, lambda r: r.type == "MAG_CAL_REPORT" and r.msg.compass_id == rep.compass_id, 3.0)
    assert seen is not None and other.since(0, "MAG_CAL_PROGRESS")
    # the daemon is alive and still answers commands after the whole dialogue
    assert _ack(gcs, M.MAV_CMD_DO_ACCEPT_MAG_CAL) == M.MAV_RESULT_ACCEPTED


def test_accelerometer_calibration_six_positions_answered_like_qgroundcontrol(gcs):
    mark = gcs.mark()
    assert _ack(gcs, M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 0, 1) == M.MAV_RESULT_ACCEPTED
    asked = []
    for position in range(1, 7):
        r = wait_for(gcs, lambda r, p=position: r.type == "COMMAND_LONG"
                     and r.msg.command == M.MAV_CMD_ACCELCAL_VEHICLE_POS and r.msg.param1 == p, 5.0, since=mark)
        assert r is not None, f"the vehicle never asked for position {position}"
        assert (r.msg.target_system, r.msg.target_component) == (255, 190)
        asked.append(position)
        mark = gcs.mark()
        gcs.send(M.MAVLink_command_ack_message(0, 1, 0, 0, 0, 0))  # QGroundControl's "Next"
    done = wait_for(gcs, lambda r: r.type == "COMMAND_LONG" and r.msg.command == M.MAV_CMD_ACCELCAL_VEHICLE_POS
                    and r.msg.param1 == M.ACCELCAL_VEHICLE_POS_SUCCESS, 5.0, since=mark)
    assert done is not None
    assert asked == [1, 2, 3, 4, 5, 6]
    assert wait_for(gcs, lambda r: r.type == "STATUSTEXT" and r.msg.text == "Calibration successful", 3.0)
    texts = _texts(gcs, 0)
    assert "Place vehicle level and press any key." in texts
    assert "Place vehicle on its BACK and press any key." in texts
    assert "Calibration successful" in texts


def test_accelcal_vehicle_pos_from_the_ground_station_must_match_the_position_asked(gcs):
    assert _ack(gcs, M.MAV_CMD_ACCELCAL_VEHICLE_POS, 1) == M.MAV_RESULT_FAILED  # nothing running
    mark = gcs.mark()
    assert _ack(gcs, M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 0, 1) == M.MAV_RESULT_ACCEPTED
    assert wait_for(gcs, lambda r: r.type == "COMMAND_LONG" and r.msg.param1 == 1, 5.0, since=mark)
    assert _ack(gcs, M.MAV_CMD_ACCELCAL_VEHICLE_POS, 2) == M.MAV_RESULT_FAILED  # level is wanted
    assert _ack(gcs, M.MAV_CMD_ACCELCAL_VEHICLE_POS, 1) == M.MAV_RESULT_ACCEPTED  # MAVProxy's way
    assert wait_for(gcs, lambda r: r.type == "COMMAND_LONG" and r.msg.param1 == 2, 5.0, since=mark)
    # QGroundControl's Cancel: PREFLIGHT_CALIBRATION with all zeros ends the dialogue as failed
    mark = gcs.mark()
    assert _ack(gcs, M.MAV_CMD_PREFLIGHT_CALIBRATION) == M.MAV_RESULT_ACCEPTED
    assert wait_for(gcs, lambda r: r.type == "COMMAND_LONG"
                    and r.msg.param1 == M.ACCELCAL_VEHICLE_POS_FAILED, 3.0, since=mark)


@pytest.mark.parametrize("name, params, text, param, value", [
    ("level", (0, 0, 0, 0, 2), "Trim OK", "AHRS_TRIM_X", 0.0),  # the vehicle sits level
    ("simple accel", (0, 0, 0, 0, 4), "Accelerometer calibration complete", "INS_ACCSCAL_X", 1.0),
    ("pressure", (0, 0, 1, 0, 0), "Updating barometer calibration", "BARO1_GND_PRESS", None),
])
def test_one_shot_calibrations_as_qgroundcontrol_sends_them(gcs, name, params, text, param, value):
    """QGroundControl's Level Horizon / simple accelerometer / Calibrate Pressure buttons: it waits for
    COMMAND_ACK IN_PROGRESS then ACCEPTED ("Successfully completed"); the result is a parameter."""
    before = _param(gcs, param)
    gcs.send(M.MAVLink_param_set_message(1, 1, param.encode(), before + 0.1, M.MAV_PARAM_TYPE_REAL32))
    assert wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == param, 3.0)
    mark = gcs.mark()
    gcs.command_long(M.MAV_CMD_PREFLIGHT_CALIBRATION, *params)
    first = wait_for(gcs, is_ack(M.MAV_CMD_PREFLIGHT_CALIBRATION), 3.0, since=mark)
    assert first is not None and first.msg.result == M.MAV_RESULT_IN_PROGRESS
    final = wait_for(gcs, lambda r: is_ack(M.MAV_CMD_PREFLIGHT_CALIBRATION)(r)
                     and r.msg.result == M.MAV_RESULT_ACCEPTED, 6.0, since=mark)
    assert final is not None
    assert wait_for(gcs, lambda r: r.type == "STATUSTEXT" and text in r.msg.text, 3.0, since=mark)
    after = _param(gcs, param)
    if value is None:  # the ground pressure measured now: where it was before the nudge
        assert after == pytest.approx(before, abs=20.0) and after != pytest.approx(before + 0.1, abs=1e-3)
    else:
        assert after == pytest.approx(value)


def test_motor_test_as_qgroundcontrols_motors_page_sends_it_spins_one_output_then_stops(gcs):
    lo, hi = _param(gcs, "MOT_PWM_MIN"), _param(gcs, "MOT_PWM_MAX")  # ArduCopter's motor test range
    assert _param(gcs, "SERVO1_FUNCTION") == 33  # Motor1
    mark = gcs.mark()
    # motor 1, MOTOR_TEST_THROTTLE_PERCENT, 20 %, 1 s, motor count 0, MOTOR_TEST_ORDER_BOARD
    gcs.command_long(M.MAV_CMD_DO_MOTOR_TEST, 1, M.MOTOR_TEST_THROTTLE_PERCENT, 20, 1, 0, M.MOTOR_TEST_ORDER_BOARD)
    ack = wait_for(gcs, is_ack(M.MAV_CMD_DO_MOTOR_TEST), 3.0, since=mark)
    assert ack is not None and ack.msg.result == M.MAV_RESULT_ACCEPTED
    spinning = lo + 0.2 * (hi - lo)
    on = wait_for(gcs, lambda r: r.type == "SERVO_OUTPUT_RAW" and abs(r.msg.servo1_raw - spinning) <= 1, 3.0, since=mark)
    assert on is not None, "output 1 never showed the test throttle"
    assert on.msg.servo2_raw == lo  # only that motor
    off = wait_for(gcs, lambda r: r.type == "SERVO_OUTPUT_RAW" and r.msg.servo1_raw == lo, 3.0, since=len(gcs.received))
    assert off is not None, "the motor test did not end"
    assert wait_for(gcs, lambda r: r.type == "STATUSTEXT" and r.msg.text == "starting motor test", 1.0, since=mark)
    assert _ack(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert _ack(gcs, M.MAV_CMD_DO_MOTOR_TEST, 1, 0, 20, 1) == M.MAV_RESULT_FAILED  # ArduCopter: disarmed only


def test_radio_calibration_results_written_as_parameters_act_on_the_sticks(gcs):
    """QGroundControl's radio calibration ends by writing RCn_MIN/MAX/TRIM; they must shape the sticks
    (MANUAL_CONTROL full throttle reads as RC3_MAX) and the pre-arm RC check."""
    for name, value in (("RC3_MIN", 1100), ("RC3_MAX", 1900), ("RC3_TRIM", 1100)):
        mark = gcs.mark()
        gcs.send(M.MAVLink_param_set_message(1, 1, name.encode(), value, M.MAV_PARAM_TYPE_INT16))
        echo = wait_for(gcs, lambda r, n=name: r.type == "PARAM_VALUE" and r.msg.param_id == n, 3.0, since=mark)
        assert echo is not None and echo.msg.param_value == value
    mark = gcs.mark()
    gcs.send(M.MAVLink_manual_control_message(1, 0, 0, 1000, 0, 0))  # full throttle
    full = wait_for(gcs, lambda r: r.type == "RC_CHANNELS" and r.msg.chan3_raw == 1900, 3.0, since=mark)
    assert full is not None, "full throttle did not read as RC3_MAX"
    mark = gcs.mark()
    gcs.send(M.MAVLink_param_set_message(1, 1, b"RC3_MAX", 1600, M.MAV_PARAM_TYPE_INT16))  # a bad calibration
    assert wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == "RC3_MAX", 3.0, since=mark)
    mark = gcs.mark()
    assert _ack(gcs, M.MAV_CMD_RUN_PREARM_CHECKS) == M.MAV_RESULT_ACCEPTED
    assert wait_for(gcs, lambda r: r.type == "STATUSTEXT" and r.msg.text.startswith("PreArm: RC3_MAX"), 3.0, since=mark)
