"""The simulated world a vehicle lives in: wind, GPS reception, and the battery's chemistry.

Pure functions of parameters and simulated time. Wind: SIM_WIND_SPD (m/s) from SIM_WIND_DIR
(degrees, where it blows from, as a weather report says), with SIM_WIND_TURB (m/s) of slow,
deterministic gusts. GPS: SIM_GPS_DISABLE (1: no fix), SIM_GPS_NUMSATS, SIM_GPS_HDOP with a
small wander. Battery: current follows throttle (`Limits.cruise_current_a` at cruise throttle,
at most MAX_CURRENT_A however odd the parameters), consumption integrates it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from gcsd.vehicle.sim.limits import Limits
from gcsd.vehicle.sim.state import VehicleState

GPS_FIX_NONE = 1
GPS_FIX_3D = 3
MAX_CURRENT_A = 200.0  # whatever the parameters say (a hover throttle of 0.01...), a battery's current stays real


@dataclass(frozen=True)
class Environment:
    wind_speed_ms: float = 0.0
    wind_from_deg: float = 180.0
    wind_turbulence_ms: float = 0.0
    gps_enabled: bool = True
    gps_satellites: int = 12
    gps_hdop: float = 0.7


def apply_wind(s: VehicleState, env: Environment) -> None:
    speed = env.wind_speed_ms
    if env.wind_turbulence_ms > 0:
        t = s.time_s
        speed += env.wind_turbulence_ms * (0.6 * math.sin(0.37 * t) + 0.4 * math.sin(1.13 * t + 1.0))
    speed = max(0.0, speed)
    towards = math.radians(env.wind_from_deg + 180.0)
    s.wind_n_ms = speed * math.cos(towards)
    s.wind_e_ms = speed * math.sin(towards)


def apply_gps(s: VehicleState, env: Environment) -> None:
    if not env.gps_enabled:
        s.gps_fix_type, s.satellites, s.hdop = GPS_FIX_NONE, 0, 99.99
        return
    s.gps_fix_type = GPS_FIX_3D if env.gps_satellites >= 4 else GPS_FIX_NONE
    s.satellites = env.gps_satellites
    s.hdop = round(env.gps_hdop + 0.05 * math.sin(0.1 * s.time_s), 2)


def apply_battery(s: VehicleState, lim: Limits, dt: float) -> None:
    if s.armed:
        load = max(0.0, s.throttle_pct / 100.0) / max(lim.hover_throttle, 0.05)
        s.current_a = min(MAX_CURRENT_A, lim.idle_current_a + lim.cruise_current_a * load ** 1.5)
    else:
        s.current_a = lim.idle_current_a
    s.consumed_mah = min(max(s.capacity_mah, 0.0), s.consumed_mah + s.current_a * dt * 1000.0 / 3600.0)
