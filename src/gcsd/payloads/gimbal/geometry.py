"""Angles of the gimbal: wrapping, the pitch and yaw from the vehicle to a location, and 3-2-1 Euler
angles to and from the w, x, y, z quaternions MAVLink carries (ArduPilot's Quaternion::from_euler)."""

from __future__ import annotations

import math

from gcsd.vehicle.sim.geo import ne_m


def wrap_pi(rad: float) -> float:
    return (rad + math.pi) % (2 * math.pi) - math.pi


def clamp(v: float, lo: float, hi: float) -> float:
    return max(lo, min(hi, v))


def angles_to(from_lat: float, from_lon: float, from_alt_m: float, lat: float, lon: float,
              alt_m: float) -> tuple[float, float]:
    """(pitch, earth-frame yaw) in radians from one location to another (AP_Mount's
    get_angle_target_to_location); altitudes in the same frame."""
    north, east = ne_m(from_lat, from_lon, lat, lon)
    return math.atan2(alt_m - from_alt_m, math.hypot(north, east)), math.atan2(east, north)


def quaternion(roll: float, pitch: float, yaw: float) -> list[float]:
    """w, x, y, z of a 3-2-1 Euler rotation (ArduPilot's Quaternion::from_euler)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return [cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy]


def euler(q: list[float]) -> tuple[float, float, float]:
    """roll, pitch, yaw (rad) of a w, x, y, z quaternion."""
    w, x, y, z = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(clamp(2 * (w * y - z * x), -1.0, 1.0))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw
