"""The gimbal manager core (gcsd.payloads.gimbal.mount) with a fake clock: ArduPilot 4.6's AP_Mount answers,
slewing at a finite rate, and pointing at a location while the vehicle moves."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.payloads.gimbal.geometry import euler, quaternion
from gcsd.payloads.gimbal.mount import (
    GPS_POINT,
    MAVLINK,
    NEUTRAL,
    RC,
    RETRACT,
    SLEW_RATE_DEG_S,
    SYSID,
    Mount,
    MountParams,
    Pose,
)
from gcsd.payloads.gimbal.params import GROUP, mount_params, with_mount_params
from gcsd.vehicle.params.store import INT8, ParamDef
from gcsd.vehicle.sim.geo import offset

NAN = math.nan
HOME = (-35.363262, 149.165237, 584.0)
ACCEPTED, FAILED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_FAILED
LOCK = M.GIMBAL_MANAGER_FLAGS_ROLL_LOCK | M.GIMBAL_MANAGER_FLAGS_PITCH_LOCK


def pose(yaw_deg: float = 0.0, lat: float = HOME[0], lon: float = HOME[1], alt: float = HOME[2] + 50) -> Pose:
    return Pose(lat, lon, alt, math.radians(yaw_deg), HOME)


def settle(mount: Mount, now: float, p: Pose, seconds: float = 10.0, dt: float = 0.05) -> float:
    t = now
    while t < now + seconds:
        t += dt
        mount.step(t, p)
    return t


def degs(mount: Mount) -> list[float]:
    return [round(math.degrees(a), 3) for a in mount.attitude]


def test_default_mode_is_rc_targeting_at_the_middle_of_the_limits():
    m = Mount(MountParams(), 0.0)
    assert m.mode == RC
    settle(m, 0.0, pose())
    assert degs(m) == [0.0, -35.0, 0.0]  # (-90 + 20) / 2, as ArduPilot with centred inputs


def test_pitchyaw_angles_slew_at_the_rate_then_hold():
    m = Mount(MountParams(default_mode=NEUTRAL), 0.0)
    assert m.pitchyaw(LOCK, -45.0, 30.0, NAN, NAN, 1) == ACCEPTED
    assert m.mode == MAVLINK
    m.step(0.5, pose())
    assert degs(m)[1] == pytest.approx(-SLEW_RATE_DEG_S * 0.5)  # not there yet: a finite slew
    assert degs(m)[2] == pytest.approx(30.0)
    settle(m, 0.5, pose(), 2.0)
    assert degs(m) == [0.0, -45.0, 30.0]
    assert m.device_flags() & M.GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME
    assert not m.device_flags() & M.GIMBAL_DEVICE_FLAGS_YAW_LOCK


def test_pitchyaw_angles_are_clamped_to_the_limits():
    m = Mount(MountParams(), 0.0)
    m.pitchyaw(0, -120.0, 200.0, NAN, NAN, 0)
    settle(m, 0.0, pose())
    assert degs(m) == [0.0, -90.0, -160.0]  # pitch to MNT1_PITCH_MIN; yaw 200 is -160 in the body frame


def test_earth_locked_yaw_holds_its_heading_as_the_vehicle_turns():
    m = Mount(MountParams(), 0.0)
    m.pitchyaw(LOCK | M.GIMBAL_MANAGER_FLAGS_YAW_LOCK, 0.0, 90.0, NAN, NAN, 1)
    t = settle(m, 0.0, pose(yaw_deg=0.0))
    assert degs(m)[2] == 90.0
    settle(m, t, pose(yaw_deg=60.0))
    assert degs(m)[2] == 30.0  # body-frame yaw: still facing east
    assert m.device_flags() & M.GIMBAL_DEVICE_FLAGS_YAW_LOCK


def test_nan_angles_with_rates_mean_rate_control():
    m = Mount(MountParams(default_mode=NEUTRAL), 0.0)
    assert m.pitchyaw(0, NAN, NAN, -10.0, 20.0, 1) == ACCEPTED
    m.step(1.0, pose())
    m.step(2.0, pose())
    assert degs(m)[1] == pytest.approx(-20.0, abs=0.01)
    assert degs(m)[2] == pytest.approx(40.0, abs=0.01)


def test_all_nan_sets_only_the_yaw_lock_and_half_nan_fails():
    m = Mount(MountParams(), 0.0)
    assert m.pitchyaw(M.GIMBAL_MANAGER_FLAGS_YAW_LOCK, NAN, NAN, NAN, NAN, 1) == ACCEPTED
    assert m.yaw_lock and m.mode == RC
    assert m.status(0).flags & M.GIMBAL_MANAGER_FLAGS_YAW_LOCK
    assert m.pitchyaw(0, 10.0, NAN, NAN, 5.0, 1) == FAILED


def test_unknown_device_fails_and_retract_neutral_flags_win():
    m = Mount(MountParams(retract_deg=(0.0, -90.0, 0.0)), 0.0)
    assert m.pitchyaw(0, 0.0, 0.0, NAN, NAN, 2) == FAILED
    assert m.configure(-2, -2, (255, 190), 7) == FAILED
    assert m.pitchyaw(M.GIMBAL_MANAGER_FLAGS_RETRACT, 10.0, 10.0, NAN, NAN, 1) == ACCEPTED
    assert m.mode == RETRACT
    settle(m, 0.0, pose())
    assert degs(m) == [0.0, -90.0, 0.0]
    assert m.device_flags() & M.GIMBAL_DEVICE_FLAGS_RETRACT
    m.pitchyaw(M.GIMBAL_MANAGER_FLAGS_NEUTRAL, NAN, NAN, NAN, NAN, 0)
    assert m.mode == NEUTRAL


def test_configure_takes_and_releases_primary_control():
    m = Mount(MountParams(), 0.0)
    assert m.configure(-2, -2, (255, 190), 1) == ACCEPTED
    assert m.status_changed and m.status(0).primary_control_sysid == 255
    assert m.status(0).primary_control_compid == 190
    m.status_changed = False
    assert m.configure(-3, -3, (250, 1), 1) == ACCEPTED  # not in control: nothing changes
    assert m.control == (255, 190) and not m.status_changed
    assert m.configure(-1, -1, (250, 1), 0) == ACCEPTED
    assert m.control == (255, 190)
    assert m.configure(-3, -3, (255, 190), 1) == ACCEPTED
    assert m.control == (0, 0) and m.status_changed
    assert m.configure(245, 190, (255, 190), 1) == ACCEPTED
    assert m.control == (245, 190)
    assert m.configure(-4, 0, (255, 190), 1) == FAILED
    assert m.configure(256, 0, (255, 190), 1) == FAILED


def test_mount_control_angles_modes_and_refusals():
    m = Mount(MountParams(), 0.0)
    assert m.mount_control(-30.0, 0.0, 45.0, 0, 0, 0, MAVLINK, HOME[2], 1.0) == ACCEPTED
    settle(m, 0.0, pose())
    assert degs(m) == [0.0, -30.0, 45.0]
    assert m.mount_control(-3000.0, 0.0, 0.0, 0, 0, 0, MAVLINK, HOME[2], 2.0) == FAILED  # centidegrees
    assert m.take_texts() == ["Mount: invalid angle targets"]
    assert m.mount_control(-3000.0, 0.0, 0.0, 0, 0, 0, MAVLINK, HOME[2], 3.0) == FAILED
    assert m.take_texts() == []  # one warning per 30 s
    assert m.mount_control(0, 0, 0, 0, 0, 0, NEUTRAL, HOME[2], 4.0) == ACCEPTED and m.mode == NEUTRAL
    assert m.mount_control(0, 0, 0, 0, 0, 0, 9, HOME[2], 4.0) == FAILED
    assert m.mount_control(1.0, 1.0, 0, 0, 0, 0, GPS_POINT, HOME[2], 4.0) == FAILED
    lat, lon = offset(HOME[0], HOME[1], 100.0, 0.0)
    assert m.mount_control(0, 0, 0, 0.0, round(lat * 1e7), round(lon * 1e7), GPS_POINT, HOME[2], 5.0) == ACCEPTED
    assert m.mode == GPS_POINT and m.roi[2] == HOME[2]


def test_mount_configure_sets_a_valid_mode_and_accepts_any():
    m = Mount(MountParams(), 0.0)
    assert m.mount_configure(NEUTRAL) == ACCEPTED and m.mode == NEUTRAL
    assert m.mount_configure(42) == ACCEPTED and m.mode == NEUTRAL


def test_roi_keeps_pointing_at_the_location_while_the_vehicle_moves():
    m = Mount(MountParams(), 0.0)
    target = (*offset(HOME[0], HOME[1], 0.0, 100.0), HOME[2])  # 100 m east, on the ground
    m.set_roi(target)
    t = settle(m, 0.0, pose(alt=HOME[2] + 100))
    assert degs(m)[1] == pytest.approx(-45.0, abs=0.1)
    assert degs(m)[2] == pytest.approx(90.0, abs=0.1)
    # the vehicle flies 100 m east and turns to face north-east: the gimbal looks straight down-ish
    lat, lon = offset(HOME[0], HOME[1], -100.0, 100.0)  # now 100 m south of the target
    t = settle(m, t, Pose(lat, lon, HOME[2] + 100, math.radians(45.0), HOME))
    assert degs(m)[1] == pytest.approx(-45.0, abs=0.1)
    assert degs(m)[2] == pytest.approx(-45.0, abs=0.1)  # target due north, vehicle facing 45
    assert m.device_flags() & M.GIMBAL_DEVICE_FLAGS_YAW_LOCK
    m.set_roi(None)
    assert m.mode == RC  # back to MNT1_DEFLT_MODE


def test_roi_sysid_follows_the_target_systems_position():
    m = Mount(MountParams(), 0.0)
    m.set_target_sysid(7)
    assert m.mode == SYSID
    m.target_position(8, HOME[0] + 0.01, HOME[1], HOME[2])  # another system: ignored
    assert m.sysid_location is None
    north = offset(HOME[0], HOME[1], 50.0, 0.0)
    m.target_position(7, *north, HOME[2] + 50)
    settle(m, 0.0, pose())
    assert degs(m)[1] == pytest.approx(0.0, abs=0.1) and degs(m)[2] == pytest.approx(0.0, abs=0.1)


def test_set_attitude_quaternion_and_rates_not_both():
    m = Mount(MountParams(default_mode=NEUTRAL), 0.0)
    m.set_attitude(0, [NAN] * 4, (NAN, NAN, NAN), 1)
    m.set_attitude(0, quaternion(0.0, math.radians(-20), 0.0), (0.0, 0.0, 0.0), 1)  # both: ignored
    assert m.mode == NEUTRAL
    m.set_attitude(0, quaternion(0.0, math.radians(-20), math.radians(10)), (NAN, NAN, NAN), 1)
    settle(m, 0.0, pose())
    assert degs(m) == [0.0, -20.0, 10.0]
    m.set_attitude(0, [NAN] * 4, (0.0, 0.0, math.radians(10)), 1)
    m.step(11.0, pose())
    assert degs(m)[2] == pytest.approx(20.0, abs=0.01)


def test_messages_carry_the_limits_ids_and_attitude():
    m = Mount(MountParams(), 0.0)
    info = m.information(1234)
    assert info.gimbal_device_id == 1
    assert (info.pitch_min, info.pitch_max) == pytest.approx((math.radians(-90), math.radians(20)))
    assert info.cap_flags & M.GIMBAL_MANAGER_CAP_FLAGS_HAS_PITCH_AXIS
    assert info.cap_flags & M.GIMBAL_MANAGER_CAP_FLAGS_CAN_POINT_LOCATION_GLOBAL
    m.pitchyaw(0, -10.0, 20.0, NAN, NAN, 1)
    settle(m, 0.0, pose())
    att = m.attitude_status(99)
    _roll, pitch, yaw = euler(list(att.q))
    assert (math.degrees(pitch), math.degrees(yaw)) == pytest.approx((-10.0, 20.0))
    assert att.gimbal_device_id == 1 and math.isnan(att.delta_yaw)
    packed = att.pack(M.MAVLink(None, 1, 1))
    assert M.MAVLink(None).decode(bytearray(packed)).get_type() == "GIMBAL_DEVICE_ATTITUDE_STATUS"


def test_mount_params_follow_mnt1_type_with_ardupilots_defaults():
    defs = [ParamDef("A", INT8, 0), ParamDef("MNT1_TYPE", INT8, 0, 0, 13), ParamDef("Z", INT8, 0)]
    out = with_mount_params(defs)
    names = [d.name for d in out]
    assert names[:3] == ["A", "MNT1_TYPE", "MNT1_DEFLT_MODE"] and names[-1] == "Z"
    assert out[1].default == 7
    values = {d.name: d.default for d in out}
    assert mount_params(values.__getitem__) == MountParams()
    assert [d.name for d in with_mount_params([ParamDef("A", INT8, 0)])][1:3] == ["MNT1_TYPE", "MNT1_DEFLT_MODE"]
    assert len(GROUP) == 18
