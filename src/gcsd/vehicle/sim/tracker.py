"""Antenna tracker dynamics: it never moves; it points.

POINT aims yaw (pan) and pitch (tilt) at the setpoint's location; SCAN sweeps yaw at the
setpoint's `speed_ms` read as deg/s (SCAN_SPEED_YAW), or `yaw_rate_dps` and tilt back and forth between the pitch limits; MANUAL slews with the sticks;
anything else holds. Slew rates are `yaw_rate_dps` (pan) and `climb_ms` read as deg/s (tilt).
"""

from __future__ import annotations

import math

from gcsd.vehicle.sim.geo import distance_m, ne_m, wrap_180
from gcsd.vehicle.sim.limits import Limits
from gcsd.vehicle.sim.state import Kind, Landed, Setpoint, VehicleState


class TrackerDynamics:
    def __init__(self) -> None:
        self._scan_up = True

    def step(self, s: VehicleState, sp: Setpoint, lim: Limits, dt: float) -> None:
        s.vn_ms = s.ve_ms = s.vd_ms = 0.0
        s.alt_amsl_m = s.ground_m
        s.landed = Landed.ON_GROUND
        yaw = math.degrees(s.yaw_rad)
        pitch = math.degrees(s.pitch_rad)
        want_yaw, want_pitch = yaw, pitch
        if not s.armed:
            pass
        elif sp.kind == Kind.POINT:
            north, east = ne_m(s.lat, s.lon, sp.lat, sp.lon)
            want_yaw = math.degrees(math.atan2(east, north))
            flat = max(distance_m(s.lat, s.lon, sp.lat, sp.lon), 0.1)
            want_pitch = math.degrees(math.atan2(sp.alt_m - s.alt_amsl_m, flat))
        elif sp.kind == Kind.SCAN:
            want_yaw = yaw + (sp.speed_ms or lim.yaw_rate_dps) * dt  # the scan rate, deg/s
            if pitch >= lim.pitch_max_deg - 0.1:
                self._scan_up = False
            elif pitch <= lim.pitch_min_deg + 0.1:
                self._scan_up = True
            want_pitch = lim.pitch_max_deg if self._scan_up else lim.pitch_min_deg
        elif sp.kind == Kind.MANUAL:
            want_yaw = yaw + sp.sticks[3] * lim.yaw_rate_dps
            want_pitch = pitch + sp.sticks[1] * lim.climb_ms
        want_pitch = max(lim.pitch_min_deg, min(lim.pitch_max_deg, want_pitch))
        yaw_step = lim.yaw_rate_dps * dt
        pitch_step = lim.climb_ms * dt
        yaw += max(-yaw_step, min(yaw_step, wrap_180(want_yaw - yaw)))
        pitch += max(-pitch_step, min(pitch_step, want_pitch - pitch))
        s.yaw_rad = math.radians(yaw % 360.0)
        s.pitch_rad = math.radians(pitch)
        moving = abs(wrap_180(want_yaw - yaw)) > 0.5 or abs(want_pitch - pitch) > 0.5
        s.throttle_pct = (30 if moving else 5) if s.armed else 0


class StaticDynamics:
    """A companion computer: nothing moves."""

    def step(self, s: VehicleState, sp: Setpoint, lim: Limits, dt: float) -> None:
        s.vn_ms = s.ve_ms = s.vd_ms = 0.0
        s.throttle_pct = 0
