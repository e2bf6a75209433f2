"""ArduCopter: MAV_TYPE_QUADROTOR, ArduCopter's modes, a multirotor that hovers.

Parameters: ArduCopter 4.6's set (params/data/copter.tsv). Its settings read WPNAV_SPEED/_UP/_DN,
WPNAV_RADIUS, WPNAV_ACCEL (cm, cm/s), RTL_ALT, RTL_ALT_FINAL, RTL_SPEED, RTL_LOIT_TIME, LAND_SPEED,
LAND_ALT_LOW, LOIT_SPEED, ANGLE_MAX, ATC_SLEW_YAW, CIRCLE_RADIUS, CIRCLE_RATE, GUID_TIMEOUT,
MOT_THST_HOVER, FS_GCS_ENABLE, FS_GCS_TIMEOUT, DISARM_DELAY and the failsafe actions. Banner: "ArduCopter V4.6.3 (3fc7011a)", "Frame: QUAD/PLUS".
Commands: NAV_TAKEOFF in GUIDED (armed, on the ground), DO_MOTOR_TEST (disarmed).
"""

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.autopilot.settings import DISARM, Settings
from gcsd.vehicle.autopilot.settings import Behaviour as B
from gcsd.vehicle.sim import Limits, MultirotorDynamics
from gcsd.vehicle.types import commands, common, firmware, motors, prearm
from gcsd.vehicle.types.base import VehicleType, modes_named, stream_rates
from gcsd.vehicle.types.modes import mode_mapping

_modes = mode_mapping("acm")
_by_name = {v: k for k, v in _modes.items()}

# ArduCopter 4.6's parameters this module's settings() reads (all of them: params/data/copter.tsv).
PARAMS = (
    "WPNAV_SPEED", "WPNAV_SPEED_UP", "WPNAV_SPEED_DN", "WPNAV_RADIUS", "WPNAV_ACCEL", "RTL_ALT", "RTL_ALT_FINAL",
    "RTL_SPEED", "RTL_LOIT_TIME", "LAND_SPEED", "LAND_ALT_LOW", "LOIT_SPEED", "ANGLE_MAX", "ATC_SLEW_YAW",
    "CIRCLE_RADIUS", "CIRCLE_RATE", "GUID_TIMEOUT", "MOT_THST_HOVER", "FS_GCS_ENABLE", "FS_GCS_TIMEOUT",
    "DISARM_DELAY", "FS_THR_ENABLE", "PILOT_SPEED_UP", "PILOT_SPEED_DN", "LAND_SPEED_HIGH", "WP_YAW_BEHAVIOR",
) + common.FAILSAFE_PARAMS

GCS_ACTIONS = {1: "RTL", 2: "RTL", 3: "RTL", 4: "RTL", 5: "LAND", 6: "LAND", 7: "LAND"}
BATTERY_ACTIONS = {1: "LAND", 2: "RTL", 3: "RTL", 4: "RTL", 5: DISARM}
# FS_THR_ENABLE: 1 RTL, 2 RTL (removed in 4.0: ArduPilot treats it as 1), 3 LAND,
# 4 SmartRTL or RTL, 5 SmartRTL or LAND, 6 DO_LAND_START or RTL, 7 BRAKE then LAND
RADIO_ACTIONS = {1: "RTL", 2: "RTL", 3: "LAND", 4: "SMART_RTL", 5: "SMART_RTL", 6: "RTL", 7: "LAND"}
# WP_YAW_BEHAVIOR: 0 never change yaw, 1 face the next waypoint, 2 ... except in RTL, 3 face along
# the course (gcsd: as 1): the behaviours that keep their heading
KEEP_YAW = {0: frozenset({B.AUTO, B.GUIDED, B.RTL}), 2: frozenset({B.RTL})}
FENCE_ACTIONS = {1: "RTL", 2: "LAND", 3: "RTL", 4: "BRAKE", 5: "RTL", 6: "LAND", 7: "LAND"}


def settings(get) -> Settings:
    cm = lambda name: float(get(name)) / 100.0
    limits = Limits(
        cruise_speed_ms=cm("WPNAV_SPEED"), max_speed_ms=max(cm("LOIT_SPEED"), cm("WPNAV_SPEED")),
        accel_ms2=cm("WPNAV_ACCEL"), climb_ms=cm("WPNAV_SPEED_UP"), descent_ms=cm("WPNAV_SPEED_DN"),
        land_speed_ms=cm("LAND_SPEED"), land_alt_low_m=cm("LAND_ALT_LOW"), yaw_rate_dps=cm("ATC_SLEW_YAW"),
        angle_max_deg=min(max(cm("ANGLE_MAX"), 5.0), 80.0), wp_radius_m=cm("WPNAV_RADIUS"),
        hover_throttle=float(get("MOT_THST_HOVER")), cruise_current_a=15.0,
        pilot_climb_ms=cm("PILOT_SPEED_UP"), pilot_descent_ms=cm("PILOT_SPEED_DN") or cm("PILOT_SPEED_UP"),
        land_high_ms=cm("LAND_SPEED_HIGH") or cm("WPNAV_SPEED_DN"),  # 0: WPNAV_SPEED_DN, as ArduCopter
    )
    return Settings(
        limits=limits, rtl_alt_m=cm("RTL_ALT") if get("RTL_ALT") > 0 else -1.0,
        rtl_final_alt_m=cm("RTL_ALT_FINAL"), rtl_loiter_s=float(get("RTL_LOIT_TIME")) / 1000.0,
        rtl_speed_ms=cm("RTL_SPEED") or None, takeoff_alt_m=10.0,
        gcs_failsafe=common.action(GCS_ACTIONS, get("FS_GCS_ENABLE")), gcs_timeout_s=float(get("FS_GCS_TIMEOUT")),
        radio_failsafe=common.action(RADIO_ACTIONS, get("FS_THR_ENABLE")),
        battery_low=common.action(BATTERY_ACTIONS, get("BATT_FS_LOW_ACT")),
        battery_critical=common.action(BATTERY_ACTIONS, get("BATT_FS_CRT_ACT")),
        fence_action=common.action(FENCE_ACTIONS, get("FENCE_ACTION")),
        guided_timeout_s=float(get("GUID_TIMEOUT")), circle_radius_m=cm("CIRCLE_RADIUS"),
        circle_rate_dps=float(get("CIRCLE_RATE")), extra={"disarm_delay_s": float(get("DISARM_DELAY"))},
        keep_yaw_in=KEEP_YAW.get(int(get("WP_YAW_BEHAVIOR")), frozenset()),
    )


COPTER = VehicleType(
    name="copter",
    firmware="ArduCopter",
    banner_lines=firmware.copter_frame,
    motor_pwm=motors.copter_motor_pwm,
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
    commands=commands.COPTER_COMMANDS,
    ardupilot_stream_rates=stream_rates(0, 0, 0, 0, 0, 0, 0, 0, 0, 0),
)
