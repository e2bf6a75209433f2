"""Fixed-wing dynamics: a plane that must keep flying.

On the ground and disarmed it rests. TAKEOFF: it rolls along its heading, accelerating, and
rotates at the minimum airspeed, then climbs at `climb_ms` to the setpoint altitude. In the air
it flies at the setpoint speed (clamped between `min_airspeed_ms` and `max_airspeed_ms`) and
turns at the rate its bank limit allows (g tan(bank) / V): GOTO steers at the point, HOLD
circles it at the loiter radius (the direction from the setpoint), LAND glides down at the
point and, on touchdown, rolls to a stop. The wind adds to the ground velocity. Disarmed in the
air, it glides down.
"""

from __future__ import annotations

import math

from gcsd.vehicle.sim.geo import ne_m, offset, wrap_180
from gcsd.vehicle.sim.limits import Limits
from gcsd.vehicle.sim.state import Kind, Landed, Setpoint, VehicleState

G = 9.80665
ROLL_ACCEL_MS2 = 3.0
BRAKE_MS2 = 2.0
BANK_RATE_DPS = 60.0


class FixedWingDynamics:
    def step(self, s: VehicleState, sp: Setpoint, lim: Limits, dt: float) -> None:
        ground = s.ground_m
        height = s.alt_amsl_m - ground
        if s.on_ground or (s.landed == Landed.TAKEOFF and height < 0.5):
            self._ground(s, sp, lim, dt, ground)
            return
        if not s.armed:
            self._fly(s, math.degrees(s.yaw_rad), lim.min_airspeed_ms, -lim.descent_ms, lim, dt, ground)
            return
        kind = sp.kind
        speed = lim.cruise_speed_ms if sp.speed_ms is None else sp.speed_ms
        speed = max(lim.min_airspeed_ms, min(lim.max_airspeed_ms, speed))
        heading = math.degrees(s.yaw_rad)
        climb = 0.0
        if kind in (Kind.GOTO, Kind.HOLD, Kind.TAKEOFF, Kind.LAND):
            north, east = ne_m(s.lat, s.lon, sp.lat, sp.lon)
            dist = math.hypot(north, east)
            to_target = math.degrees(math.atan2(east, north))
            radius = sp.radius_m or lim.loiter_radius_m
            if kind == Kind.TAKEOFF:
                pass  # keep the runway heading while climbing out
            elif kind in (Kind.HOLD,) or (kind == Kind.GOTO and dist < radius * 0.9 and sp.radius_m != 0):
                # circle: tangent to the circle, pulled in or out by the radius error
                tangent = to_target - 90.0 * sp.direction
                correction = max(-60.0, min(60.0, (dist - radius) / max(radius, 1.0) * 90.0))
                heading = tangent + correction * sp.direction
            else:
                heading = to_target
            if kind == Kind.LAND:
                speed = max(lim.min_airspeed_ms, speed * 0.8)
                glide = height / max(dist, 1.0) * s.airspeed_ms
                climb = -min(lim.descent_ms, max(glide, 0.5 if dist < 30 else 0.0))
            else:
                climb = sp.alt_m - s.alt_amsl_m
        elif kind == Kind.VELOCITY:
            vn, ve, vd = sp.velocity
            if math.hypot(vn, ve) > 0.5:
                heading = math.degrees(math.atan2(ve, vn))
                speed = max(lim.min_airspeed_ms, min(lim.max_airspeed_ms, math.hypot(vn, ve)))
            climb = -vd * 5.0
        elif kind == Kind.MANUAL:
            heading += sp.sticks[0] * 45.0
            climb = -sp.sticks[1] * 20.0
        climb_rate = max(-lim.descent_ms, min(lim.climb_ms, climb * 0.5))
        self._fly(s, heading, speed, climb_rate, lim, dt, ground)
        if s.alt_amsl_m <= ground:  # touchdown
            s.alt_amsl_m = ground
            s.vd_ms = 0.0
            s.pitch_rad = s.roll_rad = 0.0
            s.landed = Landed.ON_GROUND
        else:
            s.landed = Landed.LANDING if kind == Kind.LAND else Landed.IN_AIR

    def _fly(self, s: VehicleState, heading: float, speed: float, climb: float, lim: Limits, dt: float,
             ground: float) -> None:
        s.airspeed_ms += max(-lim.accel_ms2 * dt, min(lim.accel_ms2 * dt, speed - s.airspeed_ms))
        v = max(s.airspeed_ms, 1.0)
        bank_max = math.radians(lim.angle_max_deg)
        err = wrap_180(heading - math.degrees(s.yaw_rad))
        want_bank = max(-bank_max, min(bank_max, math.radians(err) * 1.5))
        step = math.radians(BANK_RATE_DPS) * dt
        s.roll_rad += max(-step, min(step, want_bank - s.roll_rad))
        turn_rate = G * math.tan(s.roll_rad) / v
        s.yaw_rad = (s.yaw_rad + turn_rate * dt) % (2 * math.pi)
        s.vd_ms = -climb
        s.pitch_rad = max(math.radians(lim.pitch_min_deg), min(math.radians(lim.pitch_max_deg), math.asin(
            max(-1.0, min(1.0, climb / v))) + math.radians(2.0)))
        s.vn_ms = v * math.cos(s.yaw_rad) + s.wind_n_ms
        s.ve_ms = v * math.sin(s.yaw_rad) + s.wind_e_ms
        s.lat, s.lon = offset(s.lat, s.lon, s.vn_ms * dt, s.ve_ms * dt)
        s.alt_amsl_m = max(ground, s.alt_amsl_m + climb * dt)
        drive = lim.hover_throttle * (speed / max(lim.cruise_speed_ms, 1.0)) + 0.4 * climb / max(lim.climb_ms, 0.1)
        s.throttle_pct = int(max(0.0, min(1.0, drive)) * 100) if s.armed else 0

    def _ground(self, s: VehicleState, sp: Setpoint, lim: Limits, dt: float, ground: float) -> None:
        s.alt_amsl_m = ground
        s.vd_ms = 0.0
        s.roll_rad = 0.0
        if s.armed and sp.kind == Kind.TAKEOFF:
            s.landed = Landed.TAKEOFF
            s.airspeed_ms += ROLL_ACCEL_MS2 * dt
            s.throttle_pct = 100
            if s.airspeed_ms >= max(lim.min_airspeed_ms, 1.0):  # rotate
                s.alt_amsl_m = ground + 0.6
                s.landed = Landed.IN_AIR
                s.pitch_rad = math.radians(lim.pitch_max_deg * 0.75)
        else:
            s.airspeed_ms = max(0.0, s.airspeed_ms - BRAKE_MS2 * dt)
            s.throttle_pct = 0
            s.pitch_rad = 0.0
            s.landed = Landed.ON_GROUND
        gs = s.airspeed_ms
        s.vn_ms = gs * math.cos(s.yaw_rad)
        s.ve_ms = gs * math.sin(s.yaw_rad)
        s.lat, s.lon = offset(s.lat, s.lon, s.vn_ms * dt, s.ve_ms * dt)
