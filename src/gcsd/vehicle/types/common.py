"""What several vehicle types share: the simulated world and failsafe action tables.

The parameters themselves are ArduPilot's, as data (gcsd.vehicle.params.defs, params/data/<type>.tsv);
a vehicle type names the ones its `settings(get)` reads (`VehicleType.params`), so the autopilot
reloads its settings when one of them changes. Groups several types act on:

- SIM_*: the simulated world (`gcsd.vehicle.sim.environment`) and the simulation itself: SIM_SPEEDUP
  (time multiplier, starts at `vehicle.speedup`), SIM_RATE_HZ (physics steps per real second).
- FENCE_*: the geofence (`gcsd.vehicle.autopilot.fence`): enable, types (1 max altitude, 2 circle
  around home, 4 polygons and circles from the fence plan, 8 min altitude), action, limits.
- RALLY_*: RTL goes to the nearest rally point (RALLY_INCL_HOME: home counts as one), ignoring
  points further than RALLY_LIMIT_KM.
- BATT_LOW_*, BATT_CRT_*, BATT_FS_*: the battery failsafe (actions numbered per vehicle).
- RC_OVERRIDE_TIME: how long an RC_CHANNELS_OVERRIDE or MANUAL_CONTROL value holds.
"""

from __future__ import annotations

from gcsd.vehicle.sim.environment import Environment


def environment(get) -> Environment:
    return Environment(
        wind_speed_ms=float(get("SIM_WIND_SPD")), wind_from_deg=float(get("SIM_WIND_DIR")),
        wind_turbulence_ms=float(get("SIM_WIND_TURB")), gps_enabled=not get("SIM_GPS_DISABLE"),
        gps_satellites=int(get("SIM_GPS_NUMSATS")), gps_hdop=float(get("SIM_GPS_HDOP")),
    )


FAILSAFE_PARAMS = ("FENCE_ACTION", "BATT_FS_LOW_ACT", "BATT_FS_CRT_ACT")


def action(table: dict[int, str | None], code: float) -> str | None:
    """The mode (or DISARM) a failsafe action code selects; unknown codes do nothing."""
    return table.get(int(code))
