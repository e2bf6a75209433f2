"""SYS_STATUS sensor bits (gcsd.vehicle.types.health) against ArduPilot SITL's, and driven by real state.

The probe bits are ArduPilot's once its pre-arm checks passed (`sys_status_when_ready`); the two
documented settling differences (ArduPlane's TERRAIN and Rover's AHRS were still unhealthy 19 s
after SITL's boot) are the only bits allowed to differ. Each SYS_STATUS is the one the node's
stream really sent, decoded with pymavlink.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M
from vehicle_harness import Harness

PROBES = Path(__file__).resolve().parents[1] / "integration" / "data" / "ardupilot"
SETTLING = {("plane", "health"): {"TERRAIN"}, ("rover", "health"): {"AHRS"}}  # gcsd healthy, SITL not yet
EXTENDED = ("MAV_SYS_STATUS_RECOVERY_SYSTEM", "MAV_SYS_STATUS_SENSOR_LEAK")  # *_extended field bits, same values
NAMES = {getattr(M, n): n[len("MAV_SYS_STATUS_"):] for n in dir(M)
         if n.startswith("MAV_SYS_STATUS_") and n not in EXTENDED and n != "MAV_SYS_STATUS_SENSOR_ENUM_END"
         and isinstance(getattr(M, n), int)}
ACCEPTED = M.MAV_RESULT_ACCEPTED


def _names(mask: int) -> set[str]:
    return {NAMES[1 << i] for i in range(32) if mask & (1 << i) and (1 << i) in NAMES}


def _sys_status(h: Harness):
    mark = h.mark()
    h.node.link(h.channel).push(M.MAVLINK_MSG_ID_SYS_STATUS)
    h.run(0.1)
    got = h.of_type("SYS_STATUS", mark)
    assert got, "no SYS_STATUS sent"
    return got[-1]


def _bits(h: Harness) -> dict[str, set[str]]:
    m = _sys_status(h)
    return {"present": _names(m.onboard_control_sensors_present), "enabled": _names(m.onboard_control_sensors_enabled),
            "health": _names(m.onboard_control_sensors_health)}


@pytest.mark.parametrize("vehicle", ["copter", "plane", "rover"])
def test_sensor_bits_are_ardupilots_once_ready(tmp_path, vehicle):
    probe = json.loads((PROBES / f"{vehicle}-probe.json").read_text())["sys_status_when_ready"]["bits"]
    h = Harness(tmp_path, vehicle=vehicle)
    h.run(1.0)
    got = _bits(h)
    for kind in ("present", "enabled", "health"):
        allowed = SETTLING.get((vehicle, kind), set())
        assert got[kind] ^ set(probe[kind]) <= allowed, (kind, sorted(got[kind] ^ set(probe[kind])))


def test_prearm_check_bit_is_healthy_exactly_when_arming_would_pass(tmp_path):
    h = Harness(tmp_path)
    h.run(0.5)
    assert "PREARM_CHECK" in _bits(h)["health"] and not h.node.prearm_failures()
    h.set_param("RC1_MIN", 1400)  # "RC1_MIN too high": arming refused
    bits = _bits(h)
    assert "PREARM_CHECK" in bits["enabled"] and "PREARM_CHECK" not in bits["health"]
    assert h.arm() == M.MAV_RESULT_FAILED
    h.set_param("ARMING_CHECK", 0)  # no checks: arming passes, the bit is healthy
    assert "PREARM_CHECK" in _bits(h)["health"]
    assert h.arm() == ACCEPTED


def test_an_uncalibrated_compass_fails_prearm_until_calibrated(tmp_path):
    h = Harness(tmp_path)
    for axis in "XYZ":
        h.set_param(f"COMPASS_OFS_{axis}", 0.0)
    assert "Compass not calibrated" in h.node.prearm_failures()
    assert "PREARM_CHECK" not in _bits(h)["health"]
    assert h.command(M.MAV_CMD_DO_START_MAG_CAL, 0, 0, 1) == ACCEPTED
    assert h.run(10, until=lambda: not h.node.prearm_failures())
    assert "PREARM_CHECK" in _bits(h)["health"]


def test_geofence_is_unhealthy_only_during_a_real_breach(tmp_path):
    h = Harness(tmp_path)
    h.set_param("FENCE_ACTION", 0)  # report only: the vehicle stays outside
    h.set_param("FENCE_ALT_MAX", 20)
    bits = _bits(h)
    assert "GEOFENCE" in bits["present"] and "GEOFENCE" in bits["health"] and "GEOFENCE" not in bits["enabled"]
    h.set_param("FENCE_ENABLE", 1)
    h.mode("GUIDED")
    assert h.arm() == ACCEPTED
    assert h.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10) == ACCEPTED
    assert h.run(30, until=lambda: h.state.relative_alt_m > 9.5)
    bits = _bits(h)
    assert "GEOFENCE" in bits["enabled"] and "GEOFENCE" in bits["health"]  # flying inside
    lat, lon = h.state.lat, h.state.lon
    h.command_int(M.MAV_CMD_DO_REPOSITION, -1, 0, 0, 0, round(lat * 1e7), round(lon * 1e7), 30)
    assert h.run(30, until=lambda: h.state.relative_alt_m > 21)
    assert "GEOFENCE" not in _bits(h)["health"]  # above FENCE_ALT_MAX
    h.command_int(M.MAV_CMD_DO_REPOSITION, -1, 0, 0, 0, round(lat * 1e7), round(lon * 1e7), 10)
    assert h.run(30, until=lambda: h.state.relative_alt_m < 15)
    assert "GEOFENCE" in _bits(h)["health"]  # back inside


@pytest.mark.parametrize("mode, loops", [
    ("STABILIZE", {"SENSOR_ANGULAR_RATE_CONTROL", "SENSOR_ATTITUDE_STABILIZATION", "SENSOR_YAW_POSITION"}),
    ("ALT_HOLD", {"SENSOR_ANGULAR_RATE_CONTROL", "SENSOR_ATTITUDE_STABILIZATION", "SENSOR_YAW_POSITION", "SENSOR_Z_ALTITUDE_CONTROL"}),
    ("LOITER", {"SENSOR_ANGULAR_RATE_CONTROL", "SENSOR_ATTITUDE_STABILIZATION", "SENSOR_YAW_POSITION", "SENSOR_Z_ALTITUDE_CONTROL",
                "SENSOR_XY_POSITION_CONTROL"}),
])
def test_copter_control_loops_are_enabled_by_flight_mode(tmp_path, mode, loops):
    h = Harness(tmp_path)
    assert h.mode(mode) == ACCEPTED
    bits = _bits(h)
    control = {"SENSOR_ANGULAR_RATE_CONTROL", "SENSOR_ATTITUDE_STABILIZATION", "SENSOR_YAW_POSITION", "SENSOR_Z_ALTITUDE_CONTROL",
               "SENSOR_XY_POSITION_CONTROL"}
    assert bits["enabled"] & control == loops and bits["health"] & control == loops
    assert control <= bits["present"]


def test_no_gps_means_no_gps_bits_no_ahrs_and_no_prearm(tmp_path):
    h = Harness(tmp_path)
    h.set_param("SIM_GPS_DISABLE" if "SIM_GPS_DISABLE" in h.node.params else "SIM_GPS1_ENABLE",
                1 if "SIM_GPS_DISABLE" in h.node.params else 0)
    assert h.run(5, until=lambda: h.state.gps_fix_type < 3)
    bits = _bits(h)
    assert "SENSOR_GPS" not in bits["health"] and "AHRS" not in bits["health"]
    assert "PREARM_CHECK" not in bits["health"]


@pytest.mark.parametrize("vehicle", ["copter", "plane", "rover"])
def test_heartbeat_is_ardupilots_disarmed_on_the_ground(tmp_path, vehicle):
    probe = json.loads((PROBES / f"{vehicle}-probe.json").read_text())["heartbeat"]
    h = Harness(tmp_path, vehicle=vehicle)
    mark = h.mark()
    h.run(1.5)
    hb = h.of_type("HEARTBEAT", mark)[-1]
    got = {k: getattr(hb, k) for k in ("type", "autopilot", "base_mode", "custom_mode", "system_status")}
    assert got == {k: probe[k] for k in got}


def test_an_armed_copter_on_the_ground_is_standby_and_active_once_flying(tmp_path):
    """ArduCopter: STANDBY while landed, armed or not (QGroundControl's "flying" needs ACTIVE)."""
    h = Harness(tmp_path)
    h.mode("GUIDED")
    assert h.arm() == ACCEPTED
    mark = h.mark()
    h.run(1.5)
    assert h.of_type("HEARTBEAT", mark)[-1].system_status == M.MAV_STATE_STANDBY
    assert h.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5) == ACCEPTED
    assert h.run(20, until=lambda: h.state.relative_alt_m > 2)
    mark = h.mark()
    h.run(1.5)
    assert h.of_type("HEARTBEAT", mark)[-1].system_status == M.MAV_STATE_ACTIVE


def test_prearm_failures_are_shown_unasked_soon_after_they_appear_then_every_30_s(tmp_path):
    h = Harness(tmp_path)
    mark = h.mark()
    h.run(40, step=0.5)
    assert not [t for t in h.texts(mark) if t.startswith("PreArm")]  # the checks pass: nothing to say
    h.set_param("RC1_MIN", 1400)
    mark = h.mark()
    h.run(6, step=0.5)
    assert h.texts(mark).count("PreArm: RC1_MIN too high") == 1
    h.run(30, step=0.5)
    assert h.texts(mark).count("PreArm: RC1_MIN too high") == 2  # again after ArduPilot's 30 s
    h.run(25, step=0.5)  # the next display would be due within these 8 s
    assert h.arm(force=True) == ACCEPTED
    mark = h.mark()
    h.run(8, step=0.5)  # (a copter left on the ground disarms itself after DISARM_DELAY, 10 s)
    assert h.state.armed and not [t for t in h.texts(mark) if t.startswith("PreArm")]  # armed: no display
