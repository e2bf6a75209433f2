"""What each mode does, and the vehicle's settings, as data the vehicle types fill in.

A vehicle type maps each of its mode numbers to a `Behaviour`; the autopilot only ever asks
the behaviour, never the vehicle type. `Settings` is the vehicle's parameters in SI units (a
vehicle module builds it from its own parameter names), including which mode each failsafe
action code selects: ArduPilot numbers these differently per vehicle (BATT_FS_LOW_ACT 1 is
LAND on a copter and RTL on a plane).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from gcsd.vehicle.sim.limits import Limits


class Behaviour(enum.Enum):
    IDLE = "idle"  # does nothing (INITIALISING)
    MANUAL = "manual"  # follows the sticks (RC overrides, MANUAL_CONTROL)
    HOLD = "hold"  # holds where it is (LOITER, POSHOLD, BRAKE, HOLD, STOP, ALT_HOLD in the air)
    GUIDED = "guided"  # goes where the ground station says
    AUTO = "auto"  # flies the mission
    RTL = "rtl"  # returns to the nearest rally point or home
    LAND = "land"  # lands where it is
    TAKEOFF = "takeoff"  # climbs out to the takeoff altitude, then loiters (plane TAKEOFF)
    CIRCLE = "circle"  # circles the point where the mode was entered
    SURFACE = "surface"  # a sub rises to the surface
    SCAN = "scan"  # a tracker sweeps the sky
    TRACK = "track"  # a tracker points at the tracked vehicle


# What a failsafe or the end of a mission may do besides changing mode.
DISARM = "DISARM"


@dataclass(frozen=True)
class Settings:
    limits: Limits = field(default_factory=Limits)
    fixed_wing: bool = False  # must keep flying: loiters instead of hovering, needs no takeoff command
    rtl_alt_m: float = 15.0  # RTL altitude above home (negative: keep the current altitude)
    rtl_final_alt_m: float = 0.0  # after the return: 0 lands, > 0 hovers at this height
    rtl_loiter_s: float = 5.0  # pause above home before descending
    rtl_lands: bool = True
    rtl_speed_ms: float | None = None
    takeoff_alt_m: float = 10.0  # default takeoff altitude above home
    land_disarm_delay_s: float = 0.0  # after touchdown in an autonomous landing
    mission_end: str | None = None  # mode to switch to at the end of the mission; None: hold in AUTO
    gcs_failsafe: str | None = None  # mode on GCS heartbeat loss; None: disabled
    radio_failsafe: str | None = None  # mode on RC loss (gcsd.vehicle.types.rc); None: disabled
    gcs_timeout_s: float = 5.0
    battery_low: str | None = None  # mode (or DISARM) on a low battery; None: warn only
    battery_critical: str | None = None
    fence_action: str | None = None  # mode on a fence breach; None: report only
    guided_timeout_s: float = 3.0  # a velocity target without an update stops after this long
    circle_radius_m: float = 10.0
    circle_rate_dps: float = 20.0
    accept_radius_m: float | None = None  # default waypoint acceptance; None: limits.wp_radius_m
    ignore_alt_for_waypoints: bool = False  # rovers and trackers: only the horizontal distance counts
    track_sysid: int = 0  # tracker: whose GLOBAL_POSITION_INT to follow (0: the first one heard)
    keep_yaw_in: frozenset = frozenset()  # behaviours that keep their heading (WP_YAW_BEHAVIOR)
    extra: dict = field(default_factory=dict)
