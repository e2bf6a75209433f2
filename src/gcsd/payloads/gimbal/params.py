"""MNT1_* parameters with a gimbal (`vehicle.gimbal: true`), as AP_Mount_Params.

ArduPilot shows the MNT1_ group only once MNT1_TYPE is set (AP_PARAM_FLAG_ENABLE); with the
simulated gimbal MNT1_TYPE is 7 (BrushlessPWM: a stabilised brushless gimbal) and the rest of the
group follows it in ArduPilot's order, with ArduPilot's defaults and ranges. `mount_params`
reads them back into a `MountParams` (the limits, modes and angles the core uses; the MAV_MOUNT_MODE
values MNT1_DEFLT_MODE takes are named here).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.params.store import INT8, INT16, REAL32, ParamDef

MOUNT_TYPE_BRUSHLESS_PWM = 7
RETRACT, NEUTRAL, MAVLINK, RC, GPS_POINT, SYSID, HOME = (  # MAV_MOUNT_MODE, MNT1_DEFLT_MODE's values
    M.MAV_MOUNT_MODE_RETRACT, M.MAV_MOUNT_MODE_NEUTRAL, M.MAV_MOUNT_MODE_MAVLINK_TARGETING,
    M.MAV_MOUNT_MODE_RC_TARGETING, M.MAV_MOUNT_MODE_GPS_POINT, M.MAV_MOUNT_MODE_SYSID_TARGET,
    M.MAV_MOUNT_MODE_HOME_LOCATION)
VALID_MODES = frozenset(range(RETRACT, HOME + 1))


@dataclass(frozen=True, slots=True)
class MountParams:
    """MNT1_* as AP_Mount_Params (degrees)."""

    default_mode: int = RC
    rc_rate_degs: float = 0.0
    roll_min_deg: float = -30.0
    roll_max_deg: float = 30.0
    pitch_min_deg: float = -90.0
    pitch_max_deg: float = 20.0
    yaw_min_deg: float = -180.0
    yaw_max_deg: float = 180.0
    retract_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    neutral_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    sysid_default: int = 0

    @property
    def has_roll(self) -> bool:
        return self.roll_min_deg < self.roll_max_deg

    @property
    def has_pitch(self) -> bool:
        return self.pitch_min_deg < self.pitch_max_deg

    @property
    def has_pan(self) -> bool:
        return self.yaw_min_deg < self.yaw_max_deg


def _real(name: str, default: float, lo: float, hi: float, units: str, text: str) -> ParamDef:
    return ParamDef(name, REAL32, default, lo, hi, units, text)


GROUP: tuple[ParamDef, ...] = (
    ParamDef("MNT1_DEFLT_MODE", INT8, 3, 0, 6, "", "Mount default operating mode"),
    ParamDef("MNT1_RC_RATE", INT8, 0, 0, 90, "deg/s", "Mount RC Rate"),
    _real("MNT1_ROLL_MIN", -30, -180, 180, "deg", "Mount Roll angle minimum"),
    _real("MNT1_ROLL_MAX", 30, -180, 180, "deg", "Mount Roll angle maximum"),
    _real("MNT1_PITCH_MIN", -90, -90, 90, "deg", "Mount Pitch angle minimum"),
    _real("MNT1_PITCH_MAX", 20, -90, 90, "deg", "Mount Pitch angle maximum"),
    _real("MNT1_YAW_MIN", -180, -180, 180, "deg", "Mount Yaw angle minimum"),
    _real("MNT1_YAW_MAX", 180, -180, 180, "deg", "Mount Yaw angle maximum"),
    _real("MNT1_RETRACT_X", 0, -180, 180, "deg", "Mount roll angle when in retracted position"),
    _real("MNT1_RETRACT_Y", 0, -180, 180, "deg", "Mount pitch angle when in retracted position"),
    _real("MNT1_RETRACT_Z", 0, -180, 180, "deg", "Mount yaw angle when in retracted position"),
    _real("MNT1_NEUTRAL_X", 0, -180, 180, "deg", "Mount roll angle when in neutral position"),
    _real("MNT1_NEUTRAL_Y", 0, -180, 180, "deg", "Mount pitch angle when in neutral position"),
    _real("MNT1_NEUTRAL_Z", 0, -180, 180, "deg", "Mount yaw angle when in neutral position"),
    _real("MNT1_LEAD_RLL", 0, 0, 0.2, "s", "Mount Roll stabilization lead time"),
    _real("MNT1_LEAD_PTCH", 0, 0, 0.2, "s", "Mount Pitch stabilization lead time"),
    ParamDef("MNT1_SYSID_DFLT", INT16, 0, 0, 255, "", "Mount Target sysID"),
    ParamDef("MNT1_OPTIONS", INT16, 0, 0, 3, "", "Mount options"),
)
NAMES = frozenset(d.name for d in GROUP)


def with_mount_params(defs: list[ParamDef]) -> list[ParamDef]:
    """The vehicle's definitions with MNT1_TYPE set and the MNT1_ group after it (at the end, with
    its own MNT1_TYPE, for a set that has none)."""
    if not any(d.name == "MNT1_TYPE" for d in defs):
        defs = [*defs, ParamDef("MNT1_TYPE", INT8, 0, 0, 13, "", "Mount Type")]
    out: list[ParamDef] = []
    for d in defs:
        if d.name == "MNT1_TYPE":
            out.append(replace(d, default=MOUNT_TYPE_BRUSHLESS_PWM, max=max(d.max or 0, MOUNT_TYPE_BRUSHLESS_PWM)))
            out.extend(GROUP)
        elif d.name not in NAMES:
            out.append(d)
    return out


def mount_params(get) -> MountParams:
    """The core's settings from the live parameters (`get(name)`)."""
    return MountParams(
        default_mode=int(get("MNT1_DEFLT_MODE")), rc_rate_degs=float(get("MNT1_RC_RATE")),
        roll_min_deg=float(get("MNT1_ROLL_MIN")), roll_max_deg=float(get("MNT1_ROLL_MAX")),
        pitch_min_deg=float(get("MNT1_PITCH_MIN")), pitch_max_deg=float(get("MNT1_PITCH_MAX")),
        yaw_min_deg=float(get("MNT1_YAW_MIN")), yaw_max_deg=float(get("MNT1_YAW_MAX")),
        retract_deg=(float(get("MNT1_RETRACT_X")), float(get("MNT1_RETRACT_Y")), float(get("MNT1_RETRACT_Z"))),
        neutral_deg=(float(get("MNT1_NEUTRAL_X")), float(get("MNT1_NEUTRAL_Y")), float(get("MNT1_NEUTRAL_Z"))),
        sysid_default=int(get("MNT1_SYSID_DFLT")),
    )
