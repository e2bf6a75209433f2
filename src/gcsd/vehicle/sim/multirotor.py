"""Multirotor dynamics (copter, and blimp with its own limits): a point mass that holds position.

Horizontal: the desired ground velocity points at the target, at the setpoint's speed, slowed
so the vehicle can stop on the point (v = sqrt(2 a d)); the air-relative velocity is that minus
the wind, limited to `max_speed_ms`, so a weak vehicle (a blimp) drifts in a strong wind; the
velocity changes at most `accel_ms2`. Vertical: climb and descent rates, LAND descends at
`descent_ms` then `land_speed_ms` below `land_alt_low_m`, touching down on the ground. Tilt
follows acceleration and wind, capped at `angle_max_deg`; yaw turns at `yaw_rate_dps` to the
setpoint's yaw or the direction of travel. Disarmed in the air, it falls.
"""

from __future__ import annotations

import math

from gcsd.vehicle.sim.geo import ne_m, offset, wrap_180
from gcsd.vehicle.sim.limits import Limits
from gcsd.vehicle.sim.state import Kind, Landed, Setpoint, VehicleState

G = 9.80665
FALL_SPEED_MS = 8.0
HOLD_DEADBAND_M = 0.05


def _approach(current: float, target: float, step: float) -> float:
    if target > current:
        return min(target, current + step)
    return max(target, current - step)


class MultirotorDynamics:
    drifts_when_holding = False  # a blimp lets the wind carry it inside its loiter radius

    def step(self, s: VehicleState, sp: Setpoint, lim: Limits, dt: float) -> None:
        ground = s.ground_m
        if not s.armed:
            self._unpowered(s, ground, dt)
            return
        kind = sp.kind
        if kind == Kind.IDLE and s.alt_amsl_m - ground < 0.05:
            self._rest(s, ground, lim, idle=True)
            return
        vn_des, ve_des = self._horizontal(s, sp, lim)
        vd_des = self._vertical(s, sp, lim, ground)
        # air-relative command, limited, then back to ground velocity
        an, ae = vn_des - s.wind_n_ms, ve_des - s.wind_e_ms
        air = math.hypot(an, ae)
        if air > lim.max_speed_ms:
            an, ae = an * lim.max_speed_ms / air, ae * lim.max_speed_ms / air
        vn_cmd, ve_cmd = an + s.wind_n_ms, ae + s.wind_e_ms
        step = lim.accel_ms2 * dt
        dvn, dve = vn_cmd - s.vn_ms, ve_cmd - s.ve_ms
        dv = math.hypot(dvn, dve)
        if dv > step:
            dvn, dve = dvn * step / dv, dve * step / dv
        s.vn_ms += dvn
        s.ve_ms += dve
        s.vd_ms = _approach(s.vd_ms, vd_des, 2 * lim.accel_ms2 * dt)
        s.lat, s.lon = offset(s.lat, s.lon, s.vn_ms * dt, s.ve_ms * dt)
        s.alt_amsl_m -= s.vd_ms * dt
        if s.alt_amsl_m <= ground:
            s.alt_amsl_m = ground
            s.vd_ms = 0.0
            s.vn_ms = s.ve_ms = 0.0
            s.landed = Landed.TAKEOFF if kind == Kind.TAKEOFF else Landed.ON_GROUND
        else:
            s.landed = Landed.LANDING if kind == Kind.LAND else Landed.IN_AIR
            if kind == Kind.TAKEOFF and s.alt_amsl_m - ground < 1.0:
                s.landed = Landed.TAKEOFF
        self._attitude(s, dvn / dt if dt else 0.0, dve / dt if dt else 0.0, sp, lim, dt)
        air_n, air_e = s.vn_ms - s.wind_n_ms, s.ve_ms - s.wind_e_ms
        s.airspeed_ms = math.hypot(air_n, air_e)
        tilt = min(1.0, math.hypot(s.roll_rad, s.pitch_rad) / max(math.radians(lim.angle_max_deg), 1e-3))
        climb = max(-1.0, min(1.0, -s.vd_ms / max(lim.climb_ms, 0.1)))
        throttle = lim.hover_throttle * (1.0 + 0.3 * climb + 0.25 * tilt)
        if s.on_ground:
            throttle = 0.1
        s.throttle_pct = int(max(0.0, min(1.0, throttle)) * 100)

    # --- pieces ------------------------------------------------------------------------------
    def _unpowered(self, s: VehicleState, ground: float, dt: float) -> None:
        if s.alt_amsl_m > ground:
            s.vd_ms = _approach(s.vd_ms, FALL_SPEED_MS, G * dt)
            s.alt_amsl_m = max(ground, s.alt_amsl_m - s.vd_ms * dt)
            s.lat, s.lon = offset(s.lat, s.lon, s.vn_ms * dt, s.ve_ms * dt)
            s.landed = Landed.IN_AIR
            if s.alt_amsl_m > ground:
                s.throttle_pct = 0
                return
        self._rest(s, ground, None, idle=False)

    def _rest(self, s: VehicleState, ground: float, lim: Limits | None, idle: bool) -> None:
        s.alt_amsl_m = ground
        s.vn_ms = s.ve_ms = s.vd_ms = 0.0
        s.roll_rad = s.pitch_rad = 0.0
        s.airspeed_ms = 0.0
        s.landed = Landed.ON_GROUND
        s.throttle_pct = 10 if idle else 0

    def _horizontal(self, s: VehicleState, sp: Setpoint, lim: Limits) -> tuple[float, float]:
        kind = sp.kind
        if kind == Kind.VELOCITY:
            return sp.velocity[0], sp.velocity[1]
        if kind == Kind.MANUAL:
            roll, pitch = sp.sticks[0], sp.sticks[1]
            c, sn = math.cos(s.yaw_rad), math.sin(s.yaw_rad)
            fwd, right = -pitch * lim.max_speed_ms, roll * lim.max_speed_ms
            return fwd * c - right * sn, fwd * sn + right * c
        if kind in (Kind.IDLE, Kind.TAKEOFF) or (kind == Kind.LAND and sp.lat == 0.0 and sp.lon == 0.0):
            return 0.0, 0.0
        north, east = ne_m(s.lat, s.lon, sp.lat, sp.lon)
        dist = math.hypot(north, east)
        if self.drifts_when_holding and kind == Kind.HOLD and dist < (sp.radius_m or lim.loiter_radius_m):
            return s.wind_n_ms, s.wind_e_ms  # free drift with the wind inside the loiter radius
        if dist < HOLD_DEADBAND_M:
            return 0.0, 0.0
        speed = lim.cruise_speed_ms if sp.speed_ms is None else sp.speed_ms
        speed = min(speed, lim.max_speed_ms, math.sqrt(2.0 * lim.accel_ms2 * dist))
        return north / dist * speed, east / dist * speed

    def _vertical(self, s: VehicleState, sp: Setpoint, lim: Limits, ground: float) -> float:
        kind = sp.kind
        if kind == Kind.LAND:
            height = s.alt_amsl_m - ground
            high = lim.land_high_ms if lim.land_high_ms is not None else lim.descent_ms
            return lim.land_speed_ms if height < lim.land_alt_low_m else high
        if kind == Kind.VELOCITY:
            return max(-lim.climb_ms, min(lim.descent_ms, sp.velocity[2]))
        if kind == Kind.MANUAL:  # the stick as a climb rate around mid-stick, as ALT_HOLD
            throttle = sp.sticks[2]
            up = lim.pilot_climb_ms if lim.pilot_climb_ms is not None else lim.climb_ms
            down = lim.pilot_descent_ms if lim.pilot_descent_ms is not None else lim.descent_ms
            return -throttle * (up if throttle > 0 else down)
        if kind == Kind.IDLE:
            return lim.descent_ms
        error = sp.alt_m - s.alt_amsl_m  # positive: climb
        rate = min(lim.climb_ms, math.sqrt(2.0 * lim.accel_ms2 * abs(error))) if error > 0 else \
            min(lim.descent_ms, math.sqrt(2.0 * lim.accel_ms2 * abs(error)))
        return -math.copysign(rate, error) if abs(error) > 0.01 else 0.0

    def _attitude(self, s: VehicleState, an: float, ae: float, sp: Setpoint, lim: Limits, dt: float) -> None:
        # lean into the acceleration and against the wind (drag ~ air velocity)
        air_n, air_e = s.vn_ms - s.wind_n_ms, s.ve_ms - s.wind_e_ms
        fn, fe = an + 0.15 * air_n, ae + 0.15 * air_e
        c, sn = math.cos(s.yaw_rad), math.sin(s.yaw_rad)
        fwd, right = fn * c + fe * sn, -fn * sn + fe * c
        limit = math.radians(lim.angle_max_deg)
        s.pitch_rad = max(-limit, min(limit, -math.atan2(fwd, G)))
        s.roll_rad = max(-limit, min(limit, math.atan2(right, G)))
        if sp.yaw_deg is not None:
            want = sp.yaw_deg
        elif s.groundspeed_ms > 1.0 and sp.kind in (Kind.GOTO, Kind.VELOCITY):
            want = math.degrees(math.atan2(s.ve_ms, s.vn_ms))
        else:
            return
        err = wrap_180(want - math.degrees(s.yaw_rad))
        turn = max(-lim.yaw_rate_dps * dt, min(lim.yaw_rate_dps * dt, err))
        s.yaw_rad = math.radians((math.degrees(s.yaw_rad) + turn) % 360.0)


class BlimpDynamics(MultirotorDynamics):
    """A blimp: a slow multirotor that drifts with the wind inside its loiter radius."""

    drifts_when_holding = True
