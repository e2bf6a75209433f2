"""The built-in simulation's vehicle state: where the vehicle is and how its battery is doing.

This is the minimal backend of the core: the vehicle rests at home, can be armed and disarmed,
changes mode, and its battery drains faster while armed. Time comes in as `now` (monotonic
seconds) and is multiplied by `speedup`. Flight dynamics for each vehicle type build on this
state later; telemetry producers only ever read it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

BATTERY_CAPACITY_MAH = 5000.0
BATTERY_CELLS = 4
CELL_FULL_V = 4.2
CELL_EMPTY_V = 3.3
IDLE_CURRENT_A = 0.5
ARMED_CURRENT_A = 12.0


@dataclass
class VehicleState:
    lat: float
    lon: float
    alt_amsl_m: float
    home_lat: float
    home_lon: float
    home_alt_m: float
    roll_rad: float = 0.0
    pitch_rad: float = 0.0
    yaw_rad: float = 0.0
    vn_ms: float = 0.0
    ve_ms: float = 0.0
    vd_ms: float = 0.0
    throttle_pct: int = 0
    armed: bool = False
    mode: int = 0
    gps_fix_type: int = 3  # GPS_FIX_TYPE_3D_FIX
    satellites: int = 12
    hdop: float = 0.7
    consumed_mah: float = 0.0
    capacity_mah: float = BATTERY_CAPACITY_MAH
    current_a: float = IDLE_CURRENT_A
    has_home: bool = True

    @property
    def relative_alt_m(self) -> float:
        return self.alt_amsl_m - self.home_alt_m

    @property
    def groundspeed_ms(self) -> float:
        return math.hypot(self.vn_ms, self.ve_ms)

    @property
    def heading_deg(self) -> float:
        return math.degrees(self.yaw_rad) % 360.0

    @property
    def battery_remaining_pct(self) -> int:
        if self.capacity_mah <= 0:
            return 100
        return max(0, min(100, round(100.0 * (1.0 - self.consumed_mah / self.capacity_mah))))

    @property
    def battery_voltage_v(self) -> float:
        frac = self.battery_remaining_pct / 100.0
        sag = 0.02 * self.current_a
        return BATTERY_CELLS * (CELL_EMPTY_V + (CELL_FULL_V - CELL_EMPTY_V) * frac) - sag


class Simulation:
    """Advances a VehicleState in simulated time."""

    def __init__(self, state: VehicleState, now: float, speedup: float = 1.0) -> None:
        self.state = state
        self.speedup = speedup
        self._last_s = now
        self.sim_time_s = 0.0

    def step(self, now: float) -> None:
        dt = (now - self._last_s) * self.speedup
        if dt <= 0:
            return
        self._last_s = now
        self.sim_time_s += dt
        s = self.state
        s.current_a = ARMED_CURRENT_A if s.armed else IDLE_CURRENT_A
        s.throttle_pct = 15 if s.armed else 0
        s.consumed_mah = min(max(s.capacity_mah, 0.0), s.consumed_mah + s.current_a * dt * 1000.0 / 3600.0)
