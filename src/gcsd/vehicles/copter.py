"""ArduCopter: MAV_TYPE_QUADROTOR, ArduCopter's modes, a multirotor that hovers.

Parameters (ArduCopter's names and units): WPNAV_SPEED/_UP/_DN, WPNAV_RADIUS, WPNAV_ACCEL
(cm, cm/s), RTL_ALT, RTL_ALT_FINAL, RTL_SPEED, RTL_LOIT_TIME, LAND_SPEED, LAND_ALT_LOW, LOIT_SPEED, ANGLE_MAX, ATC_SLEW_YAW, CIRCLE_RADIUS, CIRCLE_RATE, GUID_TIMEOUT,
MOT_THST_HOVER, FS_GCS_ENABLE, FS_GCS_TIMEOUT, plus the shared fence, rally, battery
failsafe, RC override and SIM_ groups. Commands: NAV_TAKEOFF in GUIDED (armed, on the ground),
DO_MOTOR_TEST (disarmed).
"""

from pymavlink.dialects.v20 import ardupilotmega as M

from ..autopilot.settings import DISARM, Settings
from ..autopilot.settings import Behaviour as B
from ..params.store import INT8, INT16, INT32, REAL32
from ..params.store import ParamDef as P
from ..sim import Limits, MultirotorDynamics
from . import commands, common, prearm
from .base import VehicleType, modes_named, stream_rates
from .modes import mode_mapping

_modes = mode_mapping("acm")
_by_name = {v: k for k, v in _modes.items()}

PARAMS = (
    P("WPNAV_SPEED", INT16, 500, 20, 2000, "cm/s", "Horizontal speed to waypoints"),
    P("WPNAV_SPEED_UP", INT16, 250, 10, 1000, "cm/s", "Climb speed to waypoints"),
    P("WPNAV_SPEED_DN", INT16, 150, 10, 500, "cm/s", "Descent speed to waypoints"),
    P("WPNAV_RADIUS", INT16, 200, 5, 1000, "cm", "A waypoint is reached within this distance"),
    P("WPNAV_ACCEL", INT16, 250, 50, 500, "cm/s/s", "Horizontal acceleration"),
    P("RTL_ALT", INT32, 1500, 0, 800000, "cm", "RTL altitude above home (0: the current altitude)"),
    P("RTL_ALT_FINAL", INT32, 0, 0, 100000, "cm", "Height after RTL (0: land)"),
    P("RTL_SPEED", INT16, 0, 0, 2000, "cm/s", "RTL speed (0: WPNAV_SPEED)"),
    P("RTL_LOIT_TIME", INT32, 5000, 0, 60000, "ms", "Pause above home before descending"),
    P("LAND_SPEED", INT16, 50, 30, 200, "cm/s", "Final descent speed"),
    P("LAND_ALT_LOW", INT16, 1000, 100, 10000, "cm", "Height at which the final descent starts"),
    P("LOIT_SPEED", INT16, 1250, 20, 3500, "cm/s", "Fastest horizontal speed with the sticks or velocity targets"),
    P("ANGLE_MAX", INT16, 3000, 0, 9000, "cdeg", "Maximum lean angle (pre-arm: 1000..8000)"),
    P("ATC_SLEW_YAW", INT16, 6000, 500, 18000, "cdeg/s", "Yaw rate"),
    P("CIRCLE_RADIUS", INT32, 1000, 0, 200000, "cm", "CIRCLE mode radius"),
    P("CIRCLE_RATE", REAL32, 20.0, -90.0, 90.0, "deg/s", "CIRCLE mode turn rate"),
    P("GUID_TIMEOUT", REAL32, 3.0, 0.1, 5.0, "s", "Guided velocity targets stop after this without updates"),
    P("MOT_THST_HOVER", REAL32, 0.35, 0.125, 0.6875, "", "Hover throttle"),
    P("FS_GCS_ENABLE", INT8, 0, 0, 7, "", "GCS failsafe: 0 off, 1 RTL, 3 SmartRTL/RTL, 5 land"),
    P("FS_GCS_TIMEOUT", REAL32, 5.0, 2.0, 120.0, "s", "GCS heartbeat loss before the failsafe"),
    P("DISARM_DELAY", INT8, 10, 0, 127, "s", "Disarm after landing in a manual mode (0: never)"),
) + common.fence_params() + common.rally_params() + common.battery_failsafe_params(0, 0) \
    + common.rc_override_params()

GCS_ACTIONS = {1: "RTL", 2: "RTL", 3: "RTL", 4: "RTL", 5: "LAND", 6: "LAND", 7: "LAND"}
BATTERY_ACTIONS = {1: "LAND", 2: "RTL", 3: "RTL", 4: "RTL", 5: DISARM}
FENCE_ACTIONS = {1: "RTL", 2: "LAND", 3: "RTL", 4: "BRAKE", 5: "RTL", 6: "LAND", 7: "LAND"}


def settings(get) -> Settings:
    cm = lambda name: float(get(name)) / 100.0
    limits = Limits(
        cruise_speed_ms=cm("WPNAV_SPEED"), max_speed_ms=max(cm("LOIT_SPEED"), cm("WPNAV_SPEED")),
        accel_ms2=cm("WPNAV_ACCEL"), climb_ms=cm("WPNAV_SPEED_UP"), descent_ms=cm("WPNAV_SPEED_DN"),
        land_speed_ms=cm("LAND_SPEED"), land_alt_low_m=cm("LAND_ALT_LOW"), yaw_rate_dps=cm("ATC_SLEW_YAW"),
        angle_max_deg=min(max(cm("ANGLE_MAX"), 5.0), 80.0), wp_radius_m=cm("WPNAV_RADIUS"),
        hover_throttle=float(get("MOT_THST_HOVER")), cruise_current_a=15.0,
    )
    return Settings(
        limits=limits, rtl_alt_m=cm("RTL_ALT") if get("RTL_ALT") > 0 else -1.0,
        rtl_final_alt_m=cm("RTL_ALT_FINAL"), rtl_loiter_s=float(get("RTL_LOIT_TIME")) / 1000.0,
        rtl_speed_ms=cm("RTL_SPEED") or None, takeoff_alt_m=10.0,
        gcs_failsafe=common.action(GCS_ACTIONS, get("FS_GCS_ENABLE")), gcs_timeout_s=float(get("FS_GCS_TIMEOUT")),
        battery_low=common.action(BATTERY_ACTIONS, get("BATT_FS_LOW_ACT")),
        battery_critical=common.action(BATTERY_ACTIONS, get("BATT_FS_CRT_ACT")),
        fence_action=common.action(FENCE_ACTIONS, get("FENCE_ACTION")),
        guided_timeout_s=float(get("GUID_TIMEOUT")), circle_radius_m=cm("CIRCLE_RADIUS"),
        circle_rate_dps=float(get("CIRCLE_RATE")), extra={"disarm_delay_s": float(get("DISARM_DELAY"))},
    )


COPTER = VehicleType(
    name="copter",
    mav_type=M.MAV_TYPE_QUADROTOR,
    modes=_modes,
    initial_mode=_by_name["STABILIZE"],
    capabilities=(
        M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
        | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT | M.MAV_PROTOCOL_CAPABILITY_FLIGHT_TERMINATION
    ),
    guided_modes=frozenset({_by_name["GUIDED"], _by_name["AUTO"], _by_name["RTL"], _by_name["LAND"]}),
    manual_modes=frozenset({_by_name["ACRO"]}),
    # ArduCopter arms in manual-throttle and position modes, not in AUTO/RTL/LAND/BRAKE etc.
    armable_modes=frozenset(
        _by_name[n] for n in ("STABILIZE", "ACRO", "ALT_HOLD", "GUIDED", "LOITER", "POSHOLD", "DRIFT", "SPORT", "FLOWHOLD", "ZIGZAG")
    ),
    behaviours=modes_named(
        _modes, STABILIZE=B.MANUAL, ACRO=B.MANUAL, ALT_HOLD=B.MANUAL, DRIFT=B.MANUAL, SPORT=B.MANUAL,
        FLIP=B.MANUAL, FLOWHOLD=B.MANUAL, GUIDED_NOGPS=B.MANUAL, TURTLE=B.MANUAL, RATE_ACRO=B.MANUAL,
        SYSTEMID=B.MANUAL, AUTOTUNE=B.HOLD, ZIGZAG=B.MANUAL, POSHOLD=B.MANUAL, LOITER=B.MANUAL,
        AUTO=B.AUTO, GUIDED=B.GUIDED, RTL=B.RTL, SMART_RTL=B.RTL, AUTO_RTL=B.RTL, LAND=B.LAND,
        CIRCLE=B.CIRCLE, BRAKE=B.HOLD, FOLLOW=B.HOLD, THROW=B.HOLD, AVOID_ADSB=B.HOLD,
        AUTOROTATE=B.LAND, POSITION=B.MANUAL, OF_LOITER=B.MANUAL,
    ),
    dynamics=MultirotorDynamics,
    params=PARAMS,
    settings=settings,
    prearm_checks=prearm.FLYING_CHECKS + (prearm.angle_max,),
    commands={
        M.MAV_CMD_NAV_TAKEOFF: commands.takeoff_in_guided,
        M.MAV_CMD_DO_MOTOR_TEST: commands.motor_test,
    },
    ardupilot_stream_rates=stream_rates(0, 0, 0, 0, 0, 0, 0, 0, 0, 0),
)
