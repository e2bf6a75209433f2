"""Calibrations with a float clock through the real node: compass (services.magcal), the six-position
accelerometer dialogue (services.accelcal) and the one-shot calibrations, each result read back from
the parameters ArduPilot keeps it in."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M
from vehicle_harness import Harness

from gcsd.vehicle.services import accelcal, magcal

ACCEPTED, FAILED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_FAILED
POS = M.MAV_CMD_ACCELCAL_VEHICLE_POS


def _asked(h: Harness, since: int) -> list[int]:
    return [int(m.param1) for m in h.of_type("COMMAND_LONG", since) if m.command == POS]


# --- compass -------------------------------------------------------------------------------------
def test_every_compass_in_use_is_calibrated_and_reported(tmp_path):
    h = Harness(tmp_path)
    for name in ("COMPASS_OFS_X", "COMPASS_OFS2_X", "COMPASS_OFS3_X"):
        h.set_param(name, 0.0)
    mark = h.mark()
    assert h.command(M.MAV_CMD_DO_START_MAG_CAL, 0, 0, 1) == ACCEPTED
    h.run(magcal.MAG_CAL_S + 1)
    reports = h.of_type("MAG_CAL_REPORT", mark)
    assert sorted({r.compass_id for r in reports}) == [0, 1, 2]  # COMPASS_DEV_ID, _ID2, _ID3 are set
    assert all(r.cal_status == M.MAG_CAL_SUCCESS and r.autosaved == 1 and r.cal_mask == 0b111 for r in reports)
    for name in ("COMPASS_OFS_X", "COMPASS_OFS2_X", "COMPASS_OFS3_X"):  # the simulated magnetometers' error
        assert h.node.params.get(name) == pytest.approx(magcal.SITL_OFFSETS[0])
    assert reports[0].ofs_y == pytest.approx(magcal.SITL_OFFSETS[1])
    progress = h.of_type("MAG_CAL_PROGRESS", mark)
    assert {p.compass_id for p in progress} == {0, 1, 2}
    assert progress[-1].completion_mask != [0] * 10


def test_without_autosave_nothing_is_saved_until_accepted_and_a_running_compass_cannot_be(tmp_path):
    h = Harness(tmp_path)
    h.set_param("COMPASS_OFS_X", 0.0)
    assert h.command(M.MAV_CMD_DO_START_MAG_CAL, 1, 0, 0) == ACCEPTED  # compass 1 only
    assert h.command(M.MAV_CMD_DO_ACCEPT_MAG_CAL) == FAILED  # still running
    h.run(magcal.MAG_CAL_S + 1)
    assert h.node.params.get("COMPASS_OFS_X") == 0.0
    assert h.command(M.MAV_CMD_DO_ACCEPT_MAG_CAL) == ACCEPTED
    assert h.node.params.get("COMPASS_OFS_X") == pytest.approx(magcal.SITL_OFFSETS[0])


def test_cancel_stops_the_calibration_and_a_delay_waits_first(tmp_path):
    h = Harness(tmp_path)
    mark = h.mark()
    assert h.command(M.MAV_CMD_DO_START_MAG_CAL, 1, 0, 1, 2.0) == ACCEPTED  # 2 s delay
    h.run(1.0)
    assert {p.cal_status for p in h.of_type("MAG_CAL_PROGRESS", mark)} == {M.MAG_CAL_WAITING_TO_START}
    assert h.command(M.MAV_CMD_DO_CANCEL_MAG_CAL) == ACCEPTED
    mark = h.mark()
    h.run(magcal.MAG_CAL_S + 3)
    assert not h.of_type("MAG_CAL_PROGRESS", mark) and not h.of_type("MAG_CAL_REPORT", mark)
    assert h.of_type("HEARTBEAT", mark)  # the node kept sending


def test_compass_calibration_is_refused_armed_or_for_no_compass(tmp_path):
    h = Harness(tmp_path)
    assert h.command(M.MAV_CMD_DO_START_MAG_CAL, 0b1000, 0, 1) == FAILED  # compass 4: none
    assert h.command(M.MAV_CMD_DO_START_MAG_CAL, 300, 0, 1) == FAILED
    assert h.arm() == ACCEPTED
    mark = h.mark()
    assert h.command(M.MAV_CMD_DO_START_MAG_CAL, 0, 0, 1) == FAILED
    assert "Disarm to allow compass calibration" in h.texts(mark)


# --- accelerometer ---------------------------------------------------------------------------------
def test_six_positions_answered_with_accelcal_vehicle_pos_save_offsets_scales_and_trim(tmp_path):
    h = Harness(tmp_path)
    for name in ("INS_ACCOFFS_X", "INS_ACC2OFFS_Y", "AHRS_TRIM_X"):
        h.set_param(name, 0.5)
    mark = h.mark()
    assert h.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 0, 1) == ACCEPTED
    for position in range(1, 7):
        assert h.run(2, until=lambda p=position: p in _asked(h, mark))
        assert h.command(POS, position) == ACCEPTED
    assert h.run(2, until=lambda: accelcal.SUCCESS in _asked(h, mark))
    assert h.run(2, until=lambda: "Calibration successful" in h.texts(mark))
    assert _asked(h, mark)[:1] == [1] and accelcal.FAILURE not in _asked(h, mark)
    p = h.node.params.get
    assert p("INS_ACCOFFS_X") == pytest.approx(accelcal.FACTORY_OFFSET_MSS)  # the simulated IMU's own error
    assert p("INS_ACCSCAL_X") == pytest.approx(1.001)
    assert p("INS_ACC2OFFS_Y") == pytest.approx(0.001)  # the second IMU (INS_ACC2_ID set)
    assert p("AHRS_TRIM_X") == pytest.approx(0.0)  # level on the ground
    assert not h.node.prearm_failures()


def test_an_unanswered_dialogue_fails_and_other_calibrations_wait_for_it(tmp_path):
    h = Harness(tmp_path)
    mark = h.mark()
    assert h.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 0, 1) == ACCEPTED
    assert h.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 0, 2) == M.MAV_RESULT_TEMPORARILY_REJECTED
    assert h.command(POS, 3) == FAILED  # level is wanted first
    h.run(accelcal.IDLE_TIMEOUT_S + 1, step=0.5)
    assert accelcal.FAILURE in _asked(h, mark)
    assert h.run(2, until=lambda: "Calibration FAILED" in h.texts(mark))
    assert h.command(POS, 1) == FAILED  # nothing runs any more


def test_a_new_board_needs_the_accelerometer_calibration_before_arming(tmp_path):
    h = Harness(tmp_path)
    for axis in "XYZ":
        h.set_param(f"INS_ACCOFFS_{axis}", 0.0)
    assert "3D Accel calibration needed" in h.node.prearm_failures()
    assert h.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 0, 4) == M.MAV_RESULT_IN_PROGRESS  # simple
    h.run(3)
    assert h.node.params.get("INS_ACCOFFS_X") == pytest.approx(0.001)
    assert not h.node.prearm_failures()


# --- one-shot calibrations ---------------------------------------------------------------------------
@pytest.mark.parametrize("params, name, expected, text", [
    ((0, 0, 0, 0, 2), "AHRS_TRIM_Y", 0.0, "Trim OK"),
    ((1, 0, 0, 0, 0), "INS_GYROFFS_X", 0.0, "Gyro calibration complete"),
    ((0, 0, 1, 0, 0), "BARO1_GND_PRESS", 94502.0, "Updating barometer calibration"),
])
def test_one_shot_calibration_lands_in_arduPilots_parameter(tmp_path, params, name, expected, text):
    h = Harness(tmp_path)
    h.set_param(name, 1.0 if name != "BARO1_GND_PRESS" else 80000.0)
    mark = h.mark()
    assert h.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, *params) == M.MAV_RESULT_IN_PROGRESS
    h.run(3)
    acks = [a.result for a in h.of_type("COMMAND_ACK", mark) if a.command == M.MAV_CMD_PREFLIGHT_CALIBRATION]
    assert acks[-1] == ACCEPTED
    assert h.node.params.get(name) == pytest.approx(expected, abs=50.0 if name == "BARO1_GND_PRESS" else 1e-6)
    assert any(text in t for t in h.texts(mark))


def test_radio_trim_on_a_plane_takes_the_current_sticks_and_a_copter_has_none(tmp_path):
    plane = Harness(tmp_path / "p", vehicle="plane")
    rc4 = plane.node.params.get("RC4_TRIM")
    plane.send(M.MAVLink_rc_channels_override_message(plane.node.sysid, 1, 1550, 1450, *[65535] * 6))
    assert plane.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 1) == ACCEPTED  # ArduPlane's trim_radio
    p = plane.node.params.get
    assert (p("RC1_TRIM"), p("RC2_TRIM"), p("RC4_TRIM")) == (1550, 1450, rc4)  # yaw had no input
    copter = Harness(tmp_path / "c")
    assert copter.command(M.MAV_CMD_PREFLIGHT_CALIBRATION, 0, 0, 0, 1) == M.MAV_RESULT_UNSUPPORTED


def test_auto_reboot_reboots_once_every_compass_is_saved_and_reported(tmp_path):
    h = Harness(tmp_path)
    boots = h.node.params.get("STAT_BOOTCNT")
    mark = h.mark()
    assert h.command(M.MAV_CMD_DO_START_MAG_CAL, 0, 0, 1, 0, 1) == ACCEPTED  # autosave, auto-reboot
    assert h.run(magcal.MAG_CAL_S + 6, until=lambda: h.node.params.get("STAT_BOOTCNT") == boots + 1)
    assert len(h.of_type("MAG_CAL_REPORT", mark)) == 3 * magcal.REPORT_REPEATS  # reported first
    assert h.run(2, until=lambda: "Rebooting" in h.texts(mark))
