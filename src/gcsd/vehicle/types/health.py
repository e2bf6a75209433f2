"""SYS_STATUS sensor bits (present, enabled, healthy) as ArduPilot sets them, from real state.

ArduPilot builds the three masks in GCS::update_sensor_status_flags and each vehicle's
update_vehicle_sensor_status_flags; `../shared/ardupilot/*-probe.json` shows the result for
copter, plane and rover on SITL. Here a `SensorProfile` per vehicle type holds what is fixed
(sensors fitted, the bits ArduPilot reports healthy without a device: PROXIMITY on a copter,
LASER_POSITION on a rover) and `sensor_bits(ctx)` adds what depends on state:

| bit | present | enabled | healthy |
|---|---|---|---|
| PREARM_CHECK | always | always | `ctx.prearm_failures()` is empty (or armed: the checks passed at arming) |
| GEOFENCE | FENCE_TYPE has altitude/circle, or polygons with a fence plan loaded | FENCE_ENABLE | not breached now |
| GPS | the simulated GPS is there (fix type >= 1) | same | 3D fix |
| AHRS | always | GPS 3D fix (the EKF has its origin) | same |
| 3D_MAG | COMPASS_USE | COMPASS_USE | present |
| BATTERY | BATT_MONITOR != 0 | same | no battery failsafe |
| RC_RECEIVER | always | always | no RC failsafe |
| DIFFERENTIAL_PRESSURE (plane) | ARSPD_TYPE != 0 | same | same |
| TERRAIN (copter, plane) | TERRAIN_ENABLE | same | same (the simulated ground is known everywhere) |
| LOGGING | always | never (ArduPilot sets it only while logging armed) | always |
| rate / attitude / yaw / XY / Z control | profile | by flight mode, ArduPilot's per-vehicle mode lists | = enabled |

`system_status(ctx)` gives HEARTBEAT.system_status by the same per-vehicle rules.

Differences from the probe files, on purpose: ArduPlane SITL reported TERRAIN unhealthy and Rover
SITL AHRS unhealthy 19 s after boot, while their EKF and terrain loader were still settling;
gcsd's simulation is settled from the first second, so both are healthy.
A missing parameter counts as ArduPilot's SITL default.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.autopilot import fence as fence_check

RATE = M.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
ATTITUDE = M.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
YAW = M.MAV_SYS_STATUS_SENSOR_YAW_POSITION
XY = M.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
Z = M.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
IMU = M.MAV_SYS_STATUS_SENSOR_3D_GYRO | M.MAV_SYS_STATUS_SENSOR_3D_ACCEL | M.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
OUTPUTS = M.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS


@dataclass(frozen=True)
class SensorProfile:
    always: int  # present, enabled and healthy whatever happens
    control: int  # control loops present (enabled by mode)
    health_only: int = 0  # healthy though neither present nor enabled (ArduPilot's defaults)
    modes: dict[str, int] | None = None  # mode name -> control bits enabled in it
    terrain: bool = False
    airspeed: bool = False
    standby: str = "disarmed"  # HEARTBEAT STANDBY when: "landed" (copter), "on_ground" (plane), "HOLD"
    # (rover), "never" (a companion computer: ACTIVE)


def _modes(**groups: tuple[str, ...]) -> dict[str, int]:
    bits = {"all": RATE | ATTITUDE | YAW | XY | Z, "stab": RATE | ATTITUDE | YAW, "stab_z": RATE | ATTITUDE | YAW | Z,
            "rate_att": RATE | ATTITUDE, "rate": RATE, "nav": RATE | ATTITUDE | YAW | XY,
            "plane_nav": RATE | ATTITUDE | YAW | XY | Z, "plane_z": RATE | ATTITUDE | Z}
    return {name: bits[group] for group, names in groups.items() for name in names}


_COPTER_STAB = ("STABILIZE", "ACRO", "DRIFT", "FLIP", "TURTLE", "SYSTEMID", "RATE_ACRO", "ZIGZAG")
COPTER = SensorProfile(
    always=IMU | OUTPUTS | M.MAV_SYS_STATUS_SENSOR_PROPULSION,
    control=RATE | ATTITUDE | YAW | XY | Z,
    health_only=M.MAV_SYS_STATUS_SENSOR_PROXIMITY,
    modes=_modes(
        stab=_COPTER_STAB,
        stab_z=("ALT_HOLD", "GUIDED_NOGPS", "SPORT", "AUTOTUNE", "FLOWHOLD"),
        all=("AUTO", "AUTO_RTL", "AVOID_ADSB", "GUIDED", "LOITER", "RTL", "CIRCLE", "LAND", "POSHOLD", "BRAKE",
             "THROW", "SMART_RTL", "FOLLOW"),
    ),
    terrain=True,
    standby="landed",
)
PLANE = SensorProfile(
    always=IMU | OUTPUTS,
    control=RATE | ATTITUDE | YAW | XY | Z,
    modes=_modes(
        rate=("ACRO", "QACRO"),
        rate_att=("STABILIZE", "FBWA", "AUTOTUNE", "QSTABILIZE", "QHOVER", "QLAND", "QLOITER", "QAUTOTUNE", "TRAINING"),
        plane_z=("FBWB", "CRUISE"),
        plane_nav=("AUTO", "RTL", "LOITER", "AVOID_ADSB", "GUIDED", "CIRCLE", "QRTL", "THERMAL", "TAKEOFF",
                   "LOITERALTQLAND", "AUTOLAND"),
    ),
    terrain=True,
    airspeed=True,
    standby="landed",
)
ROVER = SensorProfile(
    always=IMU | OUTPUTS,
    control=RATE | ATTITUDE | YAW | XY,
    health_only=M.MAV_SYS_STATUS_SENSOR_LASER_POSITION,
    modes=_modes(
        rate_att=("ACRO", "STEERING", "HOLD", "SIMPLE"),
        nav=("AUTO", "GUIDED", "RTL", "SMART_RTL", "LOITER", "FOLLOW", "CIRCLE", "DOCK"),
    ),
    standby="HOLD",
)
SUB = SensorProfile(  # ArduSub: like a copter without terrain or propulsion bits
    always=IMU | OUTPUTS,
    control=RATE | ATTITUDE | YAW | XY | Z,
    modes=_modes(stab=("STABILIZE", "ACRO", "MANUAL"), stab_z=("ALT_HOLD", "SURFACE"),
                 all=("AUTO", "GUIDED", "CIRCLE", "POSHOLD", "SURFTRAK")),
)
BLIMP = SensorProfile(always=IMU | OUTPUTS, control=RATE | ATTITUDE | YAW | XY | Z,
                      modes=_modes(all=("VELOCITY", "LOITER", "RTL")))
TRACKER = SensorProfile(always=IMU | OUTPUTS, control=YAW, modes={"AUTO": YAW, "SCAN": YAW, "GUIDED": YAW})
COMPANION = SensorProfile(always=0, control=0, modes={}, standby="never")  # a companion: always ACTIVE
PROFILES = {"copter": COPTER, "plane": PLANE, "rover": ROVER, "sub": SUB, "blimp": BLIMP, "tracker": TRACKER,
            "companion": COMPANION}


def _param(ctx, name: str, default: float) -> float:
    return float(ctx.params.get(name)) if name in ctx.params else default


def _fence_bits(ctx) -> tuple[bool, bool, bool]:
    if "FENCE_TYPE" not in ctx.params:
        return False, False, True
    types = int(_param(ctx, "FENCE_TYPE", 0))
    polygons = bool(types & fence_check.POLYGON) and bool(ctx.plans.fence.stored())
    present = bool(types & (fence_check.ALT_MAX | fence_check.CIRCLE | fence_check.ALT_MIN)) or polygons
    enabled = bool(_param(ctx, "FENCE_ENABLE", 0))
    healthy = not (enabled and ctx.autopilot.failsafes.fence_breached)
    return present, enabled, healthy


def sensor_bits(ctx) -> tuple[int, int, int]:
    """(present, enabled, healthy) for the node's SYS_STATUS now."""
    profile = PROFILES.get(ctx.vehicle.name, COMPANION)
    if profile is COMPANION:
        return 0, 0, 0
    s = ctx.state
    present = enabled = healthy = profile.always
    healthy |= profile.health_only | M.MAV_SYS_STATUS_LOGGING
    present |= M.MAV_SYS_STATUS_LOGGING | M.MAV_SYS_STATUS_AHRS | M.MAV_SYS_STATUS_SENSOR_RC_RECEIVER
    enabled |= M.MAV_SYS_STATUS_SENSOR_RC_RECEIVER
    if s.failsafe not in ("Radio", "RC"):
        healthy |= M.MAV_SYS_STATUS_SENSOR_RC_RECEIVER

    present |= M.MAV_SYS_STATUS_PREARM_CHECK
    enabled |= M.MAV_SYS_STATUS_PREARM_CHECK
    if s.armed or not ctx.prearm_failures():
        healthy |= M.MAV_SYS_STATUS_PREARM_CHECK

    fence_present, fence_enabled, fence_healthy = _fence_bits(ctx)
    present |= M.MAV_SYS_STATUS_GEOFENCE if fence_present else 0
    enabled |= M.MAV_SYS_STATUS_GEOFENCE if fence_enabled else 0
    healthy |= M.MAV_SYS_STATUS_GEOFENCE if fence_healthy else 0

    if s.gps_fix_type >= 1:
        present |= M.MAV_SYS_STATUS_SENSOR_GPS
        enabled |= M.MAV_SYS_STATUS_SENSOR_GPS
    if s.gps_fix_type >= 3:
        healthy |= M.MAV_SYS_STATUS_SENSOR_GPS | M.MAV_SYS_STATUS_AHRS
        enabled |= M.MAV_SYS_STATUS_AHRS

    if _param(ctx, "COMPASS_USE", 1):
        present |= M.MAV_SYS_STATUS_SENSOR_3D_MAG
        enabled |= M.MAV_SYS_STATUS_SENSOR_3D_MAG
        healthy |= M.MAV_SYS_STATUS_SENSOR_3D_MAG
    if _param(ctx, "BATT_MONITOR", 4):
        present |= M.MAV_SYS_STATUS_SENSOR_BATTERY
        enabled |= M.MAV_SYS_STATUS_SENSOR_BATTERY
        if s.failsafe != "Battery":
            healthy |= M.MAV_SYS_STATUS_SENSOR_BATTERY
    if profile.airspeed and _param(ctx, "ARSPD_TYPE", 2):
        bit = M.MAV_SYS_STATUS_SENSOR_DIFFERENTIAL_PRESSURE
        present, enabled, healthy = present | bit, enabled | bit, healthy | bit
    if profile.terrain and _param(ctx, "TERRAIN_ENABLE", 1):
        bit = M.MAV_SYS_STATUS_TERRAIN
        present, enabled, healthy = present | bit, enabled | bit, healthy | bit

    present |= profile.control
    loops = (profile.modes or {}).get(ctx.vehicle.mode_name(s.mode), 0) & profile.control
    enabled |= loops
    healthy |= loops
    return present, enabled, healthy


def system_status(ctx) -> int:
    """HEARTBEAT.system_status as each ArduPilot vehicle sets it: CRITICAL while a failsafe is in
    force; ArduCopter STANDBY while landed (armed or not: QGroundControl then offers takeoff, not
    land), ArduPlane STANDBY unless flying, Rover ACTIVE unless in HOLD (Rover's
    vehicle_system_status); the other types STANDBY disarmed, ACTIVE armed."""
    s = ctx.state
    if s.failsafe is not None and (s.armed or not s.on_ground):
        return M.MAV_STATE_CRITICAL
    standby = PROFILES.get(ctx.vehicle.name, COMPANION).standby
    if standby == "never":
        return M.MAV_STATE_ACTIVE
    if standby == "landed":
        return M.MAV_STATE_STANDBY if s.on_ground else M.MAV_STATE_ACTIVE
    if standby == "HOLD":
        return M.MAV_STATE_STANDBY if ctx.vehicle.mode_name(s.mode) == "HOLD" else M.MAV_STATE_ACTIVE
    return M.MAV_STATE_ACTIVE if s.armed else M.MAV_STATE_STANDBY
