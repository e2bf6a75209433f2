"""Ground and water-surface dynamics (rover): drives on the ground, turns at a limited rate.

The rover aims at the target, slowing as the heading error grows (a skid-steer rover pivots in
place) and as it nears the point, and stops inside `wp_radius_m`. HOLD within the loiter radius
(`loiter_radius_m`) means stop; outside it, drive back. MANUAL: throttle and steering sticks.
It never leaves the ground.
"""

from __future__ import annotations

import math

from gcsd.vehicle.sim.geo import ne_m, offset, wrap_180
from gcsd.vehicle.sim.limits import Limits
from gcsd.vehicle.sim.state import Kind, Landed, Setpoint, VehicleState


class GroundDynamics:
    def step(self, s: VehicleState, sp: Setpoint, lim: Limits, dt: float) -> None:
        s.alt_amsl_m = s.ground_m
        s.vd_ms = 0.0
        s.landed = Landed.ON_GROUND
        speed_now = math.hypot(s.vn_ms, s.ve_ms)
        want_speed, want_heading = 0.0, math.degrees(s.yaw_rad)
        kind = sp.kind if s.armed else Kind.IDLE
        if kind in (Kind.GOTO, Kind.HOLD, Kind.LAND):
            north, east = ne_m(s.lat, s.lon, sp.lat, sp.lon)
            dist = math.hypot(north, east)
            stop_radius = lim.wp_radius_m if kind != Kind.HOLD else max(lim.loiter_radius_m, lim.wp_radius_m)
            if dist > stop_radius or (kind == Kind.GOTO and dist > 0.3 and speed_now > 0.2):
                want_heading = math.degrees(math.atan2(east, north))
                cruise = lim.cruise_speed_ms if sp.speed_ms is None else sp.speed_ms
                want_speed = min(cruise, lim.max_speed_ms, math.sqrt(2.0 * lim.accel_ms2 * dist))
        elif kind == Kind.VELOCITY:
            vn, ve, _ = sp.velocity
            want_speed = min(math.hypot(vn, ve), lim.max_speed_ms)
            if want_speed > 0.05:
                want_heading = math.degrees(math.atan2(ve, vn))
        elif kind == Kind.MANUAL:
            want_speed = max(0.0, sp.sticks[2]) * lim.max_speed_ms
            want_heading = math.degrees(s.yaw_rad) + sp.sticks[0] * lim.yaw_rate_dps
        if sp.reverse and want_speed > 0:
            want_heading += 180.0  # face away from the direction of travel
        err = wrap_180(want_heading - math.degrees(s.yaw_rad))
        turn = max(-lim.yaw_rate_dps * dt, min(lim.yaw_rate_dps * dt, err))
        s.yaw_rad = math.radians((math.degrees(s.yaw_rad) + turn) % 360.0)
        want_speed *= max(0.0, math.cos(math.radians(min(abs(err), 90.0))))  # slow down to turn
        step = lim.accel_ms2 * dt
        speed = speed_now + max(-step, min(step, want_speed - speed_now))
        sign = -1.0 if sp.reverse else 1.0
        s.vn_ms = sign * speed * math.cos(s.yaw_rad)
        s.ve_ms = sign * speed * math.sin(s.yaw_rad)
        s.lat, s.lon = offset(s.lat, s.lon, s.vn_ms * dt, s.ve_ms * dt)
        s.airspeed_ms = speed
        s.roll_rad = s.pitch_rad = 0.0
        if s.armed:
            s.throttle_pct = int(min(1.0, lim.hover_throttle * speed / max(lim.cruise_speed_ms, 0.1)) * 100)
        else:
            s.throttle_pct = 0
