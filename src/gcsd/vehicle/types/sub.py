"""ArduSub: MAV_TYPE_SUBMARINE, ArduSub's modes, a slow vehicle below the surface.

Parameters: ArduSub's (params/data/sub.tsv: the Sub-4.5 metadata's names with the captured
vehicles' types and values). Its settings read WPNAV_SPEED, WPNAV_SPEED_UP, WPNAV_SPEED_DN,
WPNAV_RADIUS, WPNAV_ACCEL (cm, cm/s), PILOT_SPEED_UP (surfacing), ANGLE_MAX (cdeg), FS_GCS_ENABLE
and the failsafe actions; ArduSub has no FS_GCS_TIMEOUT, so the GCS failsafe waits 5 s.
Commands: no takeoff (UNSUPPORTED); LAND means surface.
"""

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.autopilot.settings import DISARM, Settings
from gcsd.vehicle.autopilot.settings import Behaviour as B
from gcsd.vehicle.sim import Limits, SubmarineDynamics
from gcsd.vehicle.types import common, prearm
from gcsd.vehicle.types.base import VehicleType, modes_named, stream_rates
from gcsd.vehicle.types.modes import mode_mapping

_modes = mode_mapping("sub")
_by_name = {v: k for k, v in _modes.items()}

# ArduSub's parameters this module's settings() reads (all of them: params/data/sub.tsv).
PARAMS = (
    "WPNAV_SPEED", "WPNAV_SPEED_UP", "WPNAV_SPEED_DN", "WPNAV_RADIUS", "WPNAV_ACCEL", "PILOT_SPEED_UP", "ANGLE_MAX",
    "FS_GCS_ENABLE",
) + common.FAILSAFE_PARAMS
GCS_TIMEOUT_S = 5.0  # ArduSub has no FS_GCS_TIMEOUT parameter

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
        gcs_failsafe=common.action(GCS_ACTIONS, get("FS_GCS_ENABLE")), gcs_timeout_s=GCS_TIMEOUT_S,
        battery_low=common.action(BATTERY_ACTIONS, get("BATT_FS_LOW_ACT")),
        battery_critical=common.action(BATTERY_ACTIONS, get("BATT_FS_CRT_ACT")),
        fence_action=common.action(FENCE_ACTIONS, get("FENCE_ACTION")),
    )


SUB = VehicleType(
    name="sub",
    firmware="ArduSub",
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
