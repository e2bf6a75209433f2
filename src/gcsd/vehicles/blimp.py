"""Blimp: MAV_TYPE_AIRSHIP, Blimp's modes, a slow airship that drifts and loiters.

Parameters: MAX_VEL_XY, MAX_VEL_Z (m/s), MAX_VEL_YAW (deg/s), MAX_POS_XY (m: the loiter
tolerance inside which it lets the wind carry it), WP_RADIUS (m), FS_GCS_ENABLE, plus the
shared groups. Commands: NAV_TAKEOFF in VELOCITY or LOITER (armed, on the ground).
"""

from pymavlink.dialects.v20 import ardupilotmega as M

from ..autopilot.settings import DISARM, Settings
from ..autopilot.settings import Behaviour as B
from ..params.store import INT8, REAL32
from ..params.store import ParamDef as P
from ..sim import BlimpDynamics, Limits
from . import commands, common, prearm
from .base import VehicleType, modes_named, stream_rates
from .modes import mode_mapping

_modes = mode_mapping("blimp")
_by_name = {v: k for k, v in _modes.items()}

PARAMS = (
    P("MAX_VEL_XY", REAL32, 1.5, 0.1, 10.0, "m/s", "Horizontal speed"),
    P("MAX_VEL_Z", REAL32, 0.5, 0.1, 5.0, "m/s", "Vertical speed"),
    P("MAX_VEL_YAW", REAL32, 20.0, 1.0, 180.0, "deg/s", "Yaw rate"),
    P("MAX_POS_XY", REAL32, 5.0, 0.5, 100.0, "m", "Loiter tolerance: drift freely inside it"),
    P("WP_RADIUS", REAL32, 2.0, 0.5, 100.0, "m", "A waypoint is reached within this distance"),
    P("FS_GCS_ENABLE", INT8, 0, 0, 2, "", "GCS failsafe: 0 off, 1 land, 2 RTL"),
    P("FS_GCS_TIMEOUT", REAL32, 5.0, 2.0, 120.0, "s", "GCS heartbeat loss before the failsafe"),
) + common.fence_params(alt_max_m=50.0) + common.rally_params() + common.battery_failsafe_params(0, 0) \
    + common.rc_override_params()

GCS_ACTIONS = {1: "LAND", 2: "RTL"}
BATTERY_ACTIONS = {1: "LAND", 2: "RTL", 3: DISARM}
FENCE_ACTIONS = {1: "RTL", 2: "LAND", 3: "HOLD"}


def settings(get) -> Settings:
    xy, z = float(get("MAX_VEL_XY")), float(get("MAX_VEL_Z"))
    limits = Limits(
        cruise_speed_ms=xy, max_speed_ms=xy, accel_ms2=0.3, climb_ms=z, descent_ms=z, land_speed_ms=z * 0.5,
        land_alt_low_m=3.0, yaw_rate_dps=float(get("MAX_VEL_YAW")), angle_max_deg=5.0,
        wp_radius_m=float(get("WP_RADIUS")), loiter_radius_m=float(get("MAX_POS_XY")), hover_throttle=0.2,
        cruise_current_a=2.0,
    )
    return Settings(
        limits=limits, rtl_alt_m=-1.0, rtl_lands=False, rtl_loiter_s=0.0, takeoff_alt_m=5.0,
        gcs_failsafe=common.action(GCS_ACTIONS, get("FS_GCS_ENABLE")), gcs_timeout_s=float(get("FS_GCS_TIMEOUT")),
        battery_low=common.action(BATTERY_ACTIONS, get("BATT_FS_LOW_ACT")),
        battery_critical=common.action(BATTERY_ACTIONS, get("BATT_FS_CRT_ACT")),
        fence_action=common.action(FENCE_ACTIONS, get("FENCE_ACTION")),
    )


BLIMP = VehicleType(
    name="blimp",
    mav_type=M.MAV_TYPE_AIRSHIP,
    modes=_modes,
    initial_mode=_by_name["MANUAL"],
    capabilities=M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
    guided_modes=frozenset({_by_name[n] for n in ("AUTO", "RTL", "LOITER", "VELOCITY")}),
    manual_modes=frozenset({_by_name["MANUAL"]}),
    behaviours=modes_named(_modes, LAND=B.LAND, MANUAL=B.MANUAL, VELOCITY=B.GUIDED, LOITER=B.HOLD, RTL=B.RTL,
                           AUTO=B.AUTO, HOLD=B.HOLD),
    dynamics=BlimpDynamics,
    params=PARAMS,
    settings=settings,
    prearm_checks=prearm.FLYING_CHECKS,
    commands={M.MAV_CMD_NAV_TAKEOFF: commands.takeoff_in_guided},
    ardupilot_stream_rates=stream_rates(0, 0, 0, 0, 0, 0, 0, 0, 0, 0),
)
