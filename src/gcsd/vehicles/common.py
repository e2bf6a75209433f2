"""Parameter groups several vehicle types share, as data, and what each one drives.

- SIM_*: the simulated world (`gcsd.sim.environment`) and the simulation itself: SIM_SPEEDUP
  (time multiplier, starts at `vehicle.speedup`), SIM_RATE_HZ (physics steps per real second).
- FENCE_*: the geofence (`gcsd.autopilot.fence`): enable, types (1 max altitude, 2 circle
  around home, 4 polygons and circles from the fence plan, 8 min altitude), action, limits.
- RALLY_*: RTL goes to the nearest rally point (RALLY_INCL_HOME: home counts as one), ignoring
  points further than RALLY_LIMIT_KM.
- BATT_LOW_*, BATT_CRT_*, BATT_FS_*: the battery failsafe (actions numbered per vehicle).
- RC_OVERRIDE_TIME: how long an RC_CHANNELS_OVERRIDE or MANUAL_CONTROL value holds.
"""

from __future__ import annotations

from ..params.store import INT8, INT16, REAL32, ParamDef
from ..sim.environment import Environment

P = ParamDef


def sim_params(speedup: float) -> tuple[ParamDef, ...]:
    return (
        P("SIM_SPEEDUP", REAL32, speedup, 0.01, 1000.0, "", "Simulation time multiplier"),
        P("SIM_RATE_HZ", INT16, 25, 1, 400, "Hz", "Simulation steps per real second"),
        P("SIM_WIND_SPD", REAL32, 0.0, 0.0, 40.0, "m/s", "Simulated wind speed"),
        P("SIM_WIND_DIR", REAL32, 180.0, 0.0, 360.0, "deg", "Direction the simulated wind blows from"),
        P("SIM_WIND_TURB", REAL32, 0.0, 0.0, 10.0, "m/s", "Simulated gust amplitude"),
        P("SIM_GPS_DISABLE", INT8, 0, 0, 1, "", "1: the simulated GPS has no fix"),
        P("SIM_GPS_NUMSATS", INT8, 12, 0, 40, "", "Satellites the simulated GPS sees (< 4: no fix)"),
        P("SIM_GPS_HDOP", REAL32, 0.7, 0.1, 99.0, "", "HDOP of the simulated GPS"),
    )


def environment(get) -> Environment:
    return Environment(
        wind_speed_ms=float(get("SIM_WIND_SPD")), wind_from_deg=float(get("SIM_WIND_DIR")),
        wind_turbulence_ms=float(get("SIM_WIND_TURB")), gps_enabled=not get("SIM_GPS_DISABLE"),
        gps_satellites=int(get("SIM_GPS_NUMSATS")), gps_hdop=float(get("SIM_GPS_HDOP")),
    )


def fence_params(alt_max_m: float = 100.0, radius_m: float = 300.0) -> tuple[ParamDef, ...]:
    return (
        P("FENCE_ENABLE", INT8, 0, 0, 1, "", "Geofence enabled"),
        P("FENCE_TYPE", INT8, 7, 0, 15, "", "Fences: 1 max altitude, 2 circle, 4 polygons, 8 min altitude"),
        P("FENCE_ACTION", INT8, 1, 0, 7, "", "What a breach does (numbered per vehicle; 0 report only)"),
        P("FENCE_ALT_MAX", REAL32, alt_max_m, 10.0, 1000.0, "m", "Maximum altitude above home"),
        P("FENCE_ALT_MIN", REAL32, -10.0, -100.0, 100.0, "m", "Minimum altitude above home"),
        P("FENCE_RADIUS", REAL32, radius_m, 30.0, 10000.0, "m", "Circular fence radius around home"),
        P("FENCE_MARGIN", REAL32, 2.0, 1.0, 10.0, "m", "Distance inside a fence that must stay clear"),
    )


def rally_params() -> tuple[ParamDef, ...]:
    return (
        P("RALLY_INCL_HOME", INT8, 1, 0, 1, "", "RTL may choose home when it is nearer than any rally point"),
        P("RALLY_LIMIT_KM", REAL32, 0.3, 0.0, 100.0, "km", "Rally points further than this are ignored (0: none)"),
    )


def battery_failsafe_params(low_action: int, critical_action: int) -> tuple[ParamDef, ...]:
    return (
        P("BATT_LOW_VOLT", REAL32, 10.5, 0.0, 100.0, "V", "Low battery voltage (0: off)"),
        P("BATT_LOW_MAH", INT16, 0, 0, 32767, "mAh", "Low battery remaining capacity (0: off)"),
        P("BATT_CRT_VOLT", REAL32, 0.0, 0.0, 100.0, "V", "Critical battery voltage (0: off)"),
        P("BATT_CRT_MAH", INT16, 0, 0, 32767, "mAh", "Critical battery remaining capacity (0: off)"),
        P("BATT_FS_LOW_ACT", INT8, low_action, 0, 7, "", "Action on a low battery (numbered per vehicle)"),
        P("BATT_FS_CRT_ACT", INT8, critical_action, 0, 7, "", "Action on a critical battery"),
    )


def rc_override_params() -> tuple[ParamDef, ...]:
    return (P("RC_OVERRIDE_TIME", REAL32, 3.0, -1.0, 120.0, "s", "How long an RC override holds (-1: forever)"),)


def action(table: dict[int, str | None], code: float) -> str | None:
    """The mode (or DISARM) a failsafe action code selects; unknown codes do nothing."""
    return table.get(int(code))
