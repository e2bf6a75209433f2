"""The vehicle state every telemetry producer reads, and the setpoint the autopilot asks for.

`VehicleState` is where the vehicle is and what it is doing: position (degrees, metres above
mean sea level), attitude (radians), NED velocity (m/s), airspeed, throttle, armed and mode,
GPS quality, battery, wind, what the navigation controller is aiming at, servo and relay
outputs and RC overrides. The default backend (the simulation) writes it; an embedding
program's backend may write it instead (`gcsd.embed`). Nothing here knows the vehicle type.

`Setpoint` is what the autopilot wants the vehicle to do now: stay idle on the ground, hold a
point, go to a point, take off to an altitude, land, fly a velocity, follow the sticks, point
at a location (an antenna tracker). Backends turn it into motion.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

BATTERY_CAPACITY_MAH = 5000.0
BATTERY_CELLS = 4
CELL_FULL_V = 4.2
CELL_EMPTY_V = 3.3
IDLE_CURRENT_A = 0.5
SERVO_COUNT = 16
RELAY_COUNT = 6


class Landed(enum.IntEnum):
    """MAV_LANDED_STATE values."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


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
    airspeed_ms: float = 0.0
    throttle_pct: int = 0
    armed: bool = False
    armed_at_s: float = 0.0  # when it was last armed (the node's clock), for FLIGHT_INFORMATION
    takeoff_at_s: float | None = None  # when it left the ground (FLIGHT_INFORMATION keeps it)
    safety_on: bool = False  # MAV_CMD_DO_SET_SAFETY_SWITCH_STATE (pre-arm: "safety switch")
    mode: int = 0
    landed: Landed = Landed.ON_GROUND
    gps_fix_type: int = 3  # GPS_FIX_TYPE_3D_FIX
    satellites: int = 12
    hdop: float = 0.7
    consumed_mah: float = 0.0
    capacity_mah: float = BATTERY_CAPACITY_MAH
    current_a: float = IDLE_CURRENT_A
    has_home: bool = True
    ground_alt_m: float | None = None  # terrain (or the surface, for a sub) under the vehicle; None: home's
    wind_n_ms: float = 0.0  # the wind's velocity (where the air moves to), m/s
    wind_e_ms: float = 0.0
    # navigation: what the controller aims at (NAV_CONTROLLER_OUTPUT, POSITION_TARGET_GLOBAL_INT)
    target: tuple[float, float, float] | None = None  # lat, lon, alt AMSL
    target_bearing_deg: float = 0.0
    wp_dist_m: float = 0.0
    alt_error_m: float = 0.0
    xtrack_error_m: float = 0.0
    # outputs and inputs
    servo_override: dict[int, int] = field(default_factory=dict)  # servo n (1-based) -> PWM
    relays: list[bool] = field(default_factory=lambda: [False] * RELAY_COUNT)
    rc_override: dict[int, int] = field(default_factory=dict)  # RC channel n (1-based) -> PWM
    failsafe: str | None = None  # the failsafe in force ("GCS", "Battery", "Fence"), if any
    fence_breach_count: int = 0  # FENCE_STATUS
    fence_breach_type: int = 0  # FENCE_BREACH
    fence_breach_time_ms: int = 0
    time_s: float = 0.0  # simulated seconds since start

    @property
    def ground_m(self) -> float:
        return self.home_alt_m if self.ground_alt_m is None else self.ground_alt_m

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
    def on_ground(self) -> bool:
        return self.landed == Landed.ON_GROUND

    @property
    def battery_remaining_pct(self) -> int:
        if self.capacity_mah <= 0:
            return 100
        return max(0, min(100, round(100.0 * (1.0 - self.consumed_mah / self.capacity_mah))))

    @property
    def battery_voltage_v(self) -> float:
        frac = self.battery_remaining_pct / 100.0
        sag = 0.02 * self.current_a
        return max(0.0, BATTERY_CELLS * (CELL_EMPTY_V + (CELL_FULL_V - CELL_EMPTY_V) * frac) - sag)  # never below 0 V


class Kind(enum.Enum):
    IDLE = "idle"  # on the ground, motors at idle (or off when disarmed)
    HOLD = "hold"  # stay at (lat, lon, alt): hover, loiter circle, stop
    GOTO = "goto"  # go to (lat, lon, alt), then hold there
    TAKEOFF = "takeoff"  # climb to alt above the current point
    LAND = "land"  # descend at (lat, lon) and touch down
    VELOCITY = "velocity"  # fly `velocity` (NED m/s)
    MANUAL = "manual"  # follow `sticks`
    POINT = "point"  # point at (lat, lon, alt) without moving (antenna tracker)
    SCAN = "scan"  # sweep (antenna tracker)


@dataclass(slots=True)
class Setpoint:
    kind: Kind = Kind.IDLE
    lat: float = 0.0
    lon: float = 0.0
    alt_m: float = 0.0  # AMSL
    speed_ms: float | None = None  # horizontal speed; None: the vehicle's cruise speed
    yaw_deg: float | None = None  # None: face the direction of travel
    radius_m: float | None = None  # loiter radius; None: the vehicle's
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sticks: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)  # roll, pitch, throttle, yaw in -1..1
    direction: int = 1  # loiter direction: 1 clockwise, -1 counter-clockwise
    reverse: bool = False  # a rover drives backwards (DO_SET_REVERSE)
