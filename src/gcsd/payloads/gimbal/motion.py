"""The simulated gimbal's motion, pure: where a target points it and how fast it gets there.

Frames: roll and pitch are earth-frame (stabilised), yaw is body-frame, as
GIMBAL_DEVICE_ATTITUDE_STATUS reports it; a target's yaw may be earth-fixed (`yaw_is_ef`) and is
turned into the body frame with the vehicle's yaw. `body_angles` is a target within the MNT1_*
limits; `integrate` moves the angle a rate target has reached over dt; `aim_at` is the target for
a location (pitch from the height difference, yaw from the bearing: AP_Mount's
get_angle_target_to_location); `slew` moves the attitude towards the demand at SLEW_RATE_DEG_S per
axis (a brushless gimbal slews; it does not jump), a full-circle pan the short way round. No
clock: dt is given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gcsd.payloads.gimbal.geometry import angles_to, clamp, wrap_pi
from gcsd.payloads.gimbal.params import MountParams

SLEW_RATE_DEG_S = 60.0


@dataclass(frozen=True, slots=True)
class Pose:
    """Where the vehicle is: degrees, metres above mean sea level, yaw in radians; its home."""

    lat: float
    lon: float
    alt_amsl_m: float
    yaw_rad: float
    home: tuple[float, float, float] | None = None


@dataclass(slots=True)
class Target:
    """An angle (rad) or rate (rad/s) demand; roll and pitch earth-frame, yaw earth- or body-frame."""

    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0
    yaw_is_ef: bool = False
    is_rate: bool = False


def aim_at(pose: Pose, location: tuple[float, float, float]) -> Target:
    """The target that points at a location (lat, lon, alt AMSL): yaw earth-fixed."""
    pitch, yaw = angles_to(pose.lat, pose.lon, pose.alt_amsl_m, *location)
    return Target(0.0, pitch, yaw, True)


def integrate(p: MountParams, angle: Target, rate: Target, pose: Pose, dt: float) -> Target:
    """The angle a rate target has reached after dt more seconds, within the limits."""
    roll = clamp(angle.roll + rate.roll * dt, math.radians(p.roll_min_deg), math.radians(p.roll_max_deg))
    pitch = clamp(angle.pitch + rate.pitch * dt, math.radians(p.pitch_min_deg), math.radians(p.pitch_max_deg))
    yaw = angle.yaw
    if angle.yaw_is_ef != rate.yaw_is_ef:
        yaw = wrap_pi(yaw + pose.yaw_rad) if rate.yaw_is_ef else wrap_pi(yaw - pose.yaw_rad)
    yaw += rate.yaw * dt
    if rate.yaw_is_ef:
        yaw = wrap_pi(yaw)
    else:
        yaw = clamp(yaw, math.radians(p.yaw_min_deg), math.radians(p.yaw_max_deg))
    return Target(roll, pitch, yaw, rate.yaw_is_ef)


def body_angles(p: MountParams, t: Target, pose: Pose) -> tuple[float, float, float]:
    """(roll, pitch earth-frame, yaw body-frame) of an angle target, within the limits."""
    yaw = wrap_pi(t.yaw - pose.yaw_rad) if t.yaw_is_ef else t.yaw
    return (clamp(t.roll, math.radians(p.roll_min_deg), math.radians(p.roll_max_deg)),
            clamp(t.pitch, math.radians(p.pitch_min_deg), math.radians(p.pitch_max_deg)),
            clamp(yaw, math.radians(p.yaw_min_deg), math.radians(p.yaw_max_deg)))


def slew(p: MountParams, attitude: list[float], rates: list[float], demand: tuple[float, float, float],
         dt: float) -> None:
    """Move `attitude` towards `demand` for dt seconds at most SLEW_RATE_DEG_S per axis; `rates`
    becomes the rate each axis moved at."""
    limit = math.radians(SLEW_RATE_DEG_S) * dt
    for axis in range(3):
        error = demand[axis] - attitude[axis]
        if axis == 2 and p.yaw_max_deg - p.yaw_min_deg >= 360:
            error = wrap_pi(error)  # a full-circle pan takes the short way round
        move = clamp(error, -limit, limit)
        attitude[axis] += move
        if axis == 2:
            attitude[2] = wrap_pi(attitude[2])
        rates[axis] = move / dt
