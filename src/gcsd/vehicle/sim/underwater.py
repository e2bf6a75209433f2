"""Submarine dynamics: a slow, buoyant, holonomic vehicle below the surface.

The surface is the ground reference (`ground_m`, home's altitude): the sub never rises above it
and never goes deeper than `max_depth_m`. Armed, it moves like a multirotor with the sub's low
speeds (GOTO, HOLD, VELOCITY, MANUAL; LAND means surface). Disarmed, it floats up slowly.
"""

from __future__ import annotations

import math

from gcsd.vehicle.sim.limits import Limits
from gcsd.vehicle.sim.multirotor import MultirotorDynamics, _approach
from gcsd.vehicle.sim.state import Kind, Landed, Setpoint, VehicleState

BUOYANCY_RISE_MS = 0.2


class SubmarineDynamics:
    def __init__(self) -> None:
        self._swim = MultirotorDynamics()

    def step(self, s: VehicleState, sp: Setpoint, lim: Limits, dt: float) -> None:
        surface = s.ground_m
        if not s.armed or sp.kind == Kind.IDLE:
            s.vn_ms = _approach(s.vn_ms, 0.0, lim.accel_ms2 * dt)
            s.ve_ms = _approach(s.ve_ms, 0.0, lim.accel_ms2 * dt)
            s.vd_ms = -BUOYANCY_RISE_MS if s.alt_amsl_m < surface else 0.0
            s.alt_amsl_m = min(surface, s.alt_amsl_m - s.vd_ms * dt)
            s.throttle_pct = 0 if not s.armed else 5
        else:
            if sp.kind == Kind.LAND:  # surface
                sp = Setpoint(Kind.GOTO, s.lat, s.lon, surface, speed_ms=0.0)
            # the multirotor model with the ground far below: the sub's floor is max depth
            s.ground_alt_m = surface - lim.max_depth_m
            try:
                self._swim.step(s, sp, lim, dt)
            finally:
                s.ground_alt_m = None if surface == s.home_alt_m else surface
            if s.alt_amsl_m > surface:
                s.alt_amsl_m = surface
                s.vd_ms = max(0.0, s.vd_ms)
        s.roll_rad *= 0.5
        s.pitch_rad *= 0.5
        s.landed = Landed.ON_GROUND if s.alt_amsl_m >= surface - 0.05 else Landed.IN_AIR
        s.airspeed_ms = math.hypot(s.vn_ms, s.ve_ms)
