"""ArduSub: MAV_TYPE_SUBMARINE, ArduSub's modes, a slow vehicle below the surface.

Parameters: WPNAV_SPEED, WPNAV_SPEED_UP, WPNAV_SPEED_DN, WPNAV_RADIUS, WPNAV_ACCEL (cm, cm/s),
PILOT_SPEED_UP (surfacing), ANGLE_MAX (cdeg), FS_GCS_ENABLE, FS_GCS_TIMEOUT, plus the shared fence,
battery failsafe, RC override and SIM_ groups (no rally: a sub has no RTL). Commands: no
takeoff (UNSUPPORTED); LAND means surface.
"""

from pymavlink.dialects.v20 import ardupilotmega as M

from ..autopilot.settings import DISARM, Settings
from ..autopilot.settings import Behaviour as B
from ..params.store import INT8, INT16
from ..params.store import ParamDef as P
from ..sim import Limits, SubmarineDynamics
from . import common, prearm
from .base import VehicleType, modes_named, stream_rates
from .modes import mode_mapping

_modes = mode_mapping("sub")
_by_name = {v: k for k, v in _modes.items()}

PARAMS = (
    P("WPNAV_SPEED", INT16, 100, 20, 500, "cm/s", "Horizontal speed to waypoints"),
    P("WPNAV_SPEED_UP", INT16, 50, 10, 500, "cm/s", "Ascent speed"),
    P("WPNAV_SPEED_DN", INT16, 50, 10, 500, "cm/s", "Descent speed"),
    P("WPNAV_RADIUS", INT16, 100, 5, 1000, "cm", "A waypoint is reached within this distance"),
    P("WPNAV_ACCEL", INT16, 50, 10, 500, "cm/s/s", "Acceleration"),
    P("PILOT_SPEED_UP", INT16, 50, 10, 500, "cm/s", "Ascent rate with the sticks"),
    P("ANGLE_MAX", INT16, 3000, 0, 9000, "cdeg", "Maximum lean angle (pre-arm: 1000..8000)"),
    P("FS_GCS_ENABLE", INT8, 0, 0, 4, "", "GCS failsafe: 0 off, 1 warn, 2 disarm, 3 depth hold, 4 surface"),
    P("FS_GCS_TIMEOUT", INT8, 5, 0, 30, "s", "GCS heartbeat loss before the failsafe"),
) + common.fence_params(alt_max_m=10.0) + common.battery_failsafe_params(0, 0) + common.rc_override_params()

GCS_ACTIONS = {2: DISARM, 3: "ALT_HOLD", 4: "SURFACE"}
BATTERY_ACTIONS = {1: "SURFACE", 2: "SURFACE", 3: DISARM}
FENCE_ACTIONS = {1: "SURFACE", 2: "ALT_HOLD"}


def settings(get) -> Settings:
    cm = lambda name: float(get(name)) / 100.0
    limits = Limits(
        cruise_speed_ms=cm("WPNAV_SPEED"), max_speed_ms=cm("WPNAV_SPEED") * 1.5, accel_ms2=cm("WPNAV_ACCEL"),
        climb_ms=cm("WPNAV_SPEED_UP"), descent_ms=cm("WPNAV_SPEED_DN"), land_speed_ms=cm("PILOT_SPEED_UP"),
        yaw_rate_dps=45.0, angle_max_deg=min(max(cm("ANGLE_MAX"), 5.0), 80.0), wp_radius_m=cm("WPNAV_RADIUS"),
        hover_throttle=0.3, cruise_current_a=6.0,
    )
    return Settings(
        limits=limits, rtl_lands=False, takeoff_alt_m=0.0,
        gcs_failsafe=common.action(GCS_ACTIONS, get("FS_GCS_ENABLE")), gcs_timeout_s=float(get("FS_GCS_TIMEOUT")),
        battery_low=common.action(BATTERY_ACTIONS, get("BATT_FS_LOW_ACT")),
        battery_critical=common.action(BATTERY_ACTIONS, get("BATT_FS_CRT_ACT")),
        fence_action=common.action(FENCE_ACTIONS, get("FENCE_ACTION")),
    )


SUB = VehicleType(
    name="sub",
    mav_type=M.MAV_TYPE_SUBMARINE,
    modes=_modes,
    initial_mode=_by_name["MANUAL"],
    capabilities=M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT,
    guided_modes=frozenset({_by_name["GUIDED"], _by_name["AUTO"]}),
    manual_modes=frozenset({_by_name["MANUAL"], _by_name["ACRO"]}),
    behaviours=modes_named(
        _modes, STABILIZE=B.MANUAL, ACRO=B.MANUAL, ALT_HOLD=B.MANUAL, MANUAL=B.MANUAL, POSHOLD=B.MANUAL,
        AUTO=B.AUTO, GUIDED=B.GUIDED, CIRCLE=B.CIRCLE, SURFACE=B.SURFACE,
    ),
    dynamics=SubmarineDynamics,
    params=PARAMS,
    settings=settings,
    prearm_checks=prearm.FLYING_CHECKS + (prearm.angle_max,),
    ardupilot_stream_rates=stream_rates(2, 2, 2, 0, 3, 10, 10, 3, 0, 0),
)
