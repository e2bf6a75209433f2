"""The gimbal manager and its simulated gimbal (ArduPilot 4.6's AP_Mount_Backend), a pure core.

States (MAV_MOUNT_MODE, as ArduPilot's): RETRACT and NEUTRAL hold MNT1_RETRACT_* / MNT1_NEUTRAL_*
(body frame); MAVLINK_TARGETING holds an angle target or integrates a rate target; RC_TARGETING
(the default, MNT1_DEFLT_MODE 3) reads no RC channel (none is assigned to a MOUNT1_* function),
so it points at the middle of the limits, as ArduPilot with centred inputs and MNT1_RC_RATE 0;
GPS_POINT, HOME_LOCATION and SYSID_TARGET aim at a location every step, so the gimbal keeps
pointing at it while the vehicle moves (pitch from the height difference, yaw from the bearing).

Transitions: DO_GIMBAL_MANAGER_PITCHYAW (flags RETRACT / NEUTRAL; angles; NaN angles with rates:
rate control; all NaN: only the yaw lock), GIMBAL_MANAGER_SET_PITCHYAW / _SET_ATTITUDE (the same
as messages), DO_MOUNT_CONTROL (z = mode; MAVLINK_TARGETING: p1 pitch, p2 roll, p3 yaw in the body
frame, |pitch| > 90 etc. FAILED "Mount: invalid angle targets"; GPS_POINT: x, y, p4 alt above home),
DO_MOUNT_CONFIGURE (p1 = mode), DO_SET_ROI_LOCATION (GPS_POINT), DO_SET_ROI_NONE (back to the
default mode when in GPS_POINT), DO_SET_ROI_SYSID (SYSID_TARGET; the target's GLOBAL_POSITION_INT
gives its position). DO_GIMBAL_MANAGER_CONFIGURE: p1/p2 = the primary controller's sysid/compid,
-1 unchanged, -2 the sender, -3 release (only by the one in control); reported in
GIMBAL_MANAGER_STATUS, not enforced (as ArduPilot). Device id 0 is "the primary gimbal", 1 this one;
any other id: FAILED.

Time: `step(now, pose)` drives the simulated gimbal towards the demand of the mode for the time
since the last step (motion.py: the slew at SLEW_RATE_DEG_S per axis within the MNT1_* limits; a
rate target integrates over the same dt). Roll and pitch are earth-frame (stabilised), yaw is
body-frame, as GIMBAL_DEVICE_ATTITUDE_STATUS reports it (flag YAW_IN_VEHICLE_FRAME, plus YAW_LOCK
when the target's yaw is earth-fixed). No clock is read here.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.payloads.gimbal.geometry import clamp, euler, quaternion
from gcsd.payloads.gimbal.motion import SLEW_RATE_DEG_S, Pose, Target, aim_at, body_angles, integrate, slew
from gcsd.payloads.gimbal.params import (
    GPS_POINT,
    HOME,
    MAVLINK,
    NEUTRAL,
    RC,
    RETRACT,
    SYSID,
    VALID_MODES,
    MountParams,
)

__all__ = ["GPS_POINT", "HOME", "MAVLINK", "NEUTRAL", "RC", "RETRACT", "SLEW_RATE_DEG_S", "SYSID", "Mount",
           "MountParams", "Pose", "Target"]

WARNING_INTERVAL_S = 30.0
ACCEPTED, FAILED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_FAILED
YAW_LOCK = M.GIMBAL_MANAGER_FLAGS_YAW_LOCK


class Mount:
    def __init__(self, params: MountParams, now: float, device_id: int = 1) -> None:
        self.params = params
        self.device_id = device_id
        self.mode = params.default_mode if params.default_mode in VALID_MODES else RC
        self.target = Target()
        self._rate_angle = Target()  # the angle a rate target has reached
        self.yaw_lock = False  # the RC-targeting yaw lock (GIMBAL_MANAGER_STATUS's YAW_LOCK)
        self.roi: tuple[float, float, float] | None = None  # lat, lon, alt AMSL
        self.target_sysid = params.sysid_default
        self.sysid_location: tuple[float, float, float] | None = None
        self.control: tuple[int, int] = (0, 0)  # primary control (sysid, compid)
        self.attitude = [0.0, 0.0, 0.0]  # roll, pitch (earth frame), yaw (body frame), rad
        self.rates = [0.0, 0.0, 0.0]  # rad/s, as the last step moved
        self._last_s = now
        self._warned_s: float | None = None
        self.texts: list[str] = []  # warnings for the ground station, taken by the service
        self.status_changed = False  # GIMBAL_MANAGER_STATUS is due now (control changed)

    # --- parameters and modes ------------------------------------------------------------------
    def set_params(self, params: MountParams) -> None:
        self.params = params

    def set_mode(self, mode: int) -> bool:
        if mode not in VALID_MODES:
            return False
        self.mode = mode
        return True

    def _device_ok(self, device_id: float) -> bool:
        return device_id in (0, self.device_id)

    def _warn(self, text: str, now: float) -> None:
        if self._warned_s is None or now - self._warned_s >= WARNING_INTERVAL_S:
            self._warned_s = now
            self.texts.append("Mount: " + text)

    def set_angle_target(self, roll_deg: float, pitch_deg: float, yaw_deg: float, yaw_is_ef: bool) -> None:
        p = self.params
        roll_deg = clamp(roll_deg, p.roll_min_deg, p.roll_max_deg)
        pitch_deg = clamp(pitch_deg, p.pitch_min_deg, p.pitch_max_deg)
        if not yaw_is_ef:
            if yaw_deg > 180:
                yaw_deg -= 360
            yaw_deg = clamp(yaw_deg, p.yaw_min_deg, p.yaw_max_deg)
        self.target = Target(math.radians(roll_deg), math.radians(pitch_deg), math.radians(yaw_deg), yaw_is_ef)
        self.mode = MAVLINK

    def set_rate_target(self, roll_degs: float, pitch_degs: float, yaw_degs: float, yaw_is_ef: bool) -> None:
        angle = self._angles_now()
        self.target = Target(math.radians(roll_degs), math.radians(pitch_degs), math.radians(yaw_degs), yaw_is_ef,
                             is_rate=True)
        self._rate_angle = angle
        self.mode = MAVLINK

    def set_roi(self, location: tuple[float, float, float] | None) -> None:
        """DO_SET_ROI_LOCATION (lat, lon, alt AMSL) or, with None, DO_SET_ROI_NONE."""
        if location is None:
            self.roi = None
            if self.mode == GPS_POINT:
                self.set_mode(self.params.default_mode)
            return
        self.roi = location
        self.mode = GPS_POINT

    def set_target_sysid(self, sysid: int) -> None:
        self.target_sysid = sysid
        self.mode = SYSID

    def target_position(self, sysid: int, lat: float, lon: float, alt_amsl_m: float) -> None:
        """A system's GLOBAL_POSITION_INT: the location SYSID_TARGET points at, if it is that system."""
        if sysid == self.target_sysid and all(math.isfinite(v) for v in (lat, lon, alt_amsl_m)):
            self.sysid_location = (lat, lon, alt_amsl_m)

    # --- commands (MAV_RESULT) -----------------------------------------------------------------
    def pitchyaw(self, flags: int, pitch_deg: float, yaw_deg: float, pitch_degs: float, yaw_degs: float,
                 device_id: float) -> int:
        """DO_GIMBAL_MANAGER_PITCHYAW and GIMBAL_MANAGER_SET_PITCHYAW."""
        if not self._device_ok(device_id):
            return FAILED
        if flags & M.GIMBAL_MANAGER_FLAGS_RETRACT:
            self.set_mode(RETRACT)
            return ACCEPTED
        if flags & M.GIMBAL_MANAGER_FLAGS_NEUTRAL:
            self.set_mode(NEUTRAL)
            return ACCEPTED
        yaw_ef = bool(flags & YAW_LOCK)
        if not math.isnan(pitch_deg) and not math.isnan(yaw_deg):
            self.set_angle_target(0.0, pitch_deg, yaw_deg, yaw_ef)
            return ACCEPTED
        if not math.isnan(pitch_degs) and not math.isnan(yaw_degs):
            self.set_rate_target(0.0, pitch_degs, yaw_degs, yaw_ef)
            return ACCEPTED
        if all(math.isnan(v) for v in (pitch_deg, yaw_deg, pitch_degs, yaw_degs)):
            self.yaw_lock = yaw_ef
            return ACCEPTED
        return FAILED

    def set_attitude(self, flags: int, q: list[float], rates_rads: tuple[float, float, float],
                     device_id: int) -> None:
        """GIMBAL_MANAGER_SET_ATTITUDE: a quaternion or angular rates (not both)."""
        if not self._device_ok(device_id):
            return
        if flags & M.GIMBAL_MANAGER_FLAGS_RETRACT:
            self.set_mode(RETRACT)
            return
        if flags & M.GIMBAL_MANAGER_FLAGS_NEUTRAL:
            self.set_mode(NEUTRAL)
            return
        q_given = not any(math.isnan(v) for v in q)
        rates_given = not any(math.isnan(v) for v in rates_rads)
        if q_given == rates_given:
            return
        yaw_ef = bool(flags & YAW_LOCK)
        if q_given:
            if sum(v * v for v in q) < 1e-6:
                return
            roll, pitch, yaw = euler(q)
            self.set_angle_target(math.degrees(roll), math.degrees(pitch), math.degrees(yaw), yaw_ef)
        else:
            self.set_rate_target(*(math.degrees(r) for r in rates_rads), yaw_ef)

    def configure(self, sysid: float, compid: float, sender: tuple[int, int], device_id: float) -> int:
        """DO_GIMBAL_MANAGER_CONFIGURE: who has primary control."""
        if not self._device_ok(device_id):
            return FAILED
        if not (-3 <= sysid <= 255 and -3 <= compid <= 255):
            return FAILED
        before = self.control
        code = int(sysid)
        if code == -2:
            self.control = sender
        elif code == -3:
            if self.control == sender:
                self.control = (0, 0)
        elif code != -1:
            self.control = (code, int(compid))
        if self.control != before:
            self.status_changed = True
        return ACCEPTED

    def mount_control(self, pitch_deg: float, roll_deg: float, yaw_deg: float, alt_m: float, lat_e7: int,
                      lon_e7: int, mode: float, home_alt_m: float, now: float) -> int:
        """DO_MOUNT_CONTROL: z is the mode; angles in degrees (yaw body-frame) or a location."""
        mode = int(mode)
        if mode in (RETRACT, NEUTRAL, RC, HOME):
            self.set_mode(mode)
            return ACCEPTED
        if mode == MAVLINK:
            if abs(pitch_deg) > 90 or abs(roll_deg) > 180 or abs(yaw_deg) > 360:
                self._warn("invalid angle targets", now)
                return FAILED
            self.set_angle_target(roll_deg, pitch_deg, yaw_deg, False)
            return ACCEPTED
        if mode == GPS_POINT:
            if pitch_deg != 0 and roll_deg != 0 and lat_e7 == 0 and lon_e7 == 0:
                self._warn("GPS_POINT target invalid", now)
                return FAILED
            self.set_roi((lat_e7 / 1e7, lon_e7 / 1e7, home_alt_m + int(alt_m)))
            return ACCEPTED
        return FAILED

    def mount_configure(self, mode: float) -> int:
        """DO_MOUNT_CONFIGURE: p1 the mode; an unknown mode changes nothing, still ACCEPTED (as ArduPilot)."""
        self.set_mode(int(mode))
        return ACCEPTED

    # --- time --------------------------------------------------------------------------------
    def _angles_now(self) -> Target:
        return Target(self.attitude[0], self.attitude[1], self.attitude[2], False)

    def demand(self, pose: Pose, dt: float) -> tuple[float, float, float]:
        """The body-frame (roll, pitch earth-frame, yaw body-frame) angles the gimbal is driven to now."""
        p = self.params
        mode = self.mode
        if mode == RETRACT:
            return tuple(math.radians(v) for v in p.retract_deg)
        if mode == NEUTRAL:
            return tuple(math.radians(v) for v in p.neutral_deg)
        if mode == RC:
            roll = math.radians((p.roll_min_deg + p.roll_max_deg) / 2)
            pitch = math.radians((p.pitch_min_deg + p.pitch_max_deg) / 2)
            yaw = 0.0 if self.yaw_lock else math.radians((p.yaw_min_deg + p.yaw_max_deg) / 2)
            self.target = Target(roll, pitch, yaw, self.yaw_lock)
        elif mode in (GPS_POINT, HOME, SYSID):
            location = {GPS_POINT: self.roi, HOME: pose.home, SYSID: self.sysid_location}[mode]
            if location is not None:
                self.target = aim_at(pose, location)
        elif self.target.is_rate:
            self._rate_angle = integrate(p, self._rate_angle, self.target, pose, dt)
            return body_angles(p, self._rate_angle, pose)
        return body_angles(p, self.target, pose)

    def step(self, now: float, pose: Pose) -> None:
        """Slew towards the demand for the time since the last step."""
        dt = now - self._last_s
        if dt <= 0:
            return
        self._last_s = now
        slew(self.params, self.attitude, self.rates, self.demand(pose, dt), dt)

    # --- what the manager says ---------------------------------------------------------------
    def yaw_locked(self) -> bool:
        if self.mode in (RETRACT, NEUTRAL):
            return False
        if self.mode == MAVLINK:
            return self.target.yaw_is_ef
        if self.mode == RC:
            return self.yaw_lock
        return True

    def device_flags(self) -> int:
        return ((M.GIMBAL_DEVICE_FLAGS_RETRACT if self.mode == RETRACT else 0)
                | (M.GIMBAL_DEVICE_FLAGS_NEUTRAL if self.mode == NEUTRAL else 0)
                | M.GIMBAL_DEVICE_FLAGS_ROLL_LOCK | M.GIMBAL_DEVICE_FLAGS_PITCH_LOCK
                | M.GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME
                | (M.GIMBAL_DEVICE_FLAGS_YAW_LOCK if self.yaw_locked() else 0))

    def capability_flags(self) -> int:
        p = self.params
        flags = (M.GIMBAL_MANAGER_CAP_FLAGS_HAS_RETRACT | M.GIMBAL_MANAGER_CAP_FLAGS_HAS_NEUTRAL
                 | M.GIMBAL_MANAGER_CAP_FLAGS_HAS_RC_INPUTS | M.GIMBAL_MANAGER_CAP_FLAGS_CAN_POINT_LOCATION_LOCAL
                 | M.GIMBAL_MANAGER_CAP_FLAGS_CAN_POINT_LOCATION_GLOBAL)
        if p.has_roll:
            flags |= (M.GIMBAL_MANAGER_CAP_FLAGS_HAS_ROLL_AXIS | M.GIMBAL_MANAGER_CAP_FLAGS_HAS_ROLL_FOLLOW
                      | M.GIMBAL_MANAGER_CAP_FLAGS_HAS_ROLL_LOCK)
        if p.has_pitch:
            flags |= (M.GIMBAL_MANAGER_CAP_FLAGS_HAS_PITCH_AXIS | M.GIMBAL_MANAGER_CAP_FLAGS_HAS_PITCH_FOLLOW
                      | M.GIMBAL_MANAGER_CAP_FLAGS_HAS_PITCH_LOCK)
        if p.has_pan:
            flags |= (M.GIMBAL_MANAGER_CAP_FLAGS_HAS_YAW_AXIS | M.GIMBAL_MANAGER_CAP_FLAGS_HAS_YAW_FOLLOW
                      | M.GIMBAL_MANAGER_CAP_FLAGS_HAS_YAW_LOCK)
        return flags

    def information(self, time_ms: int):
        p = self.params
        r = math.radians
        return M.MAVLink_gimbal_manager_information_message(
            time_ms, self.capability_flags(), self.device_id, r(p.roll_min_deg), r(p.roll_max_deg),
            r(p.pitch_min_deg), r(p.pitch_max_deg), r(p.yaw_min_deg), r(p.yaw_max_deg))

    def status(self, time_ms: int):
        flags = M.GIMBAL_MANAGER_FLAGS_ROLL_LOCK | M.GIMBAL_MANAGER_FLAGS_PITCH_LOCK
        if self.yaw_lock:
            flags |= YAW_LOCK
        return M.MAVLink_gimbal_manager_status_message(time_ms, flags, self.device_id, *self.control, 0, 0)

    def attitude_status(self, time_ms: int, target: tuple[int, int] = (0, 0)):
        return M.MAVLink_gimbal_device_attitude_status_message(
            *target, time_ms, self.device_flags(), quaternion(*self.attitude), *self.rates, 0,
            math.nan, math.nan, self.device_id)

    def take_texts(self) -> list[str]:
        texts, self.texts = self.texts, []
        return texts
