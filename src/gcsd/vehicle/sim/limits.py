"""What a vehicle can do, in SI units: the numbers the dynamics and the autopilot obey.

Each vehicle type builds its `Limits` from its own parameters (WPNAV_SPEED in cm/s for a
copter, AIRSPEED_CRUISE in m/s for a plane, CRUISE_SPEED for a rover...), so the units of the
parameters stay in the vehicle package and the simulation only sees metres and seconds.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Limits:
    cruise_speed_ms: float = 5.0  # horizontal speed to waypoints
    max_speed_ms: float = 12.0  # horizontal speed limit (sticks, velocity targets)
    accel_ms2: float = 2.5
    climb_ms: float = 2.5
    descent_ms: float = 1.5
    pilot_climb_ms: float | None = None  # throttle stick at full (copter PILOT_SPEED_UP); None: climb_ms
    pilot_descent_ms: float | None = None  # ...and at zero (PILOT_SPEED_DN); None: descent_ms
    land_speed_ms: float = 0.5  # final descent, below land_alt_low_m
    land_alt_low_m: float = 10.0
    land_high_ms: float | None = None  # LAND above land_alt_low_m (copter LAND_SPEED_HIGH); None: descent_ms
    yaw_rate_dps: float = 90.0
    angle_max_deg: float = 30.0  # lean (copter) or bank (plane) limit
    wp_radius_m: float = 2.0  # a waypoint is reached within this distance
    loiter_radius_m: float = 60.0  # plane and blimp loiter circles, rover loiter tolerance
    min_airspeed_ms: float = 0.0  # plane: stall margin
    max_airspeed_ms: float = 30.0
    pitch_max_deg: float = 20.0
    pitch_min_deg: float = -25.0
    hover_throttle: float = 0.35  # fraction of full throttle to hover or cruise
    cruise_current_a: float = 15.0  # battery current at hover or cruise throttle
    idle_current_a: float = 0.5
    max_depth_m: float = 100.0  # sub: how deep it may go
