"""ArduRover: MAV_TYPE_GROUND_ROVER, Rover's modes, a vehicle that drives and stops.

Parameters: ArduRover 4.6's set (params/data/rover.tsv). Its settings read CRUISE_SPEED (m/s),
CRUISE_THROTTLE (%), WP_SPEED (m/s, 0: CRUISE_SPEED), WP_RADIUS, LOIT_RADIUS (m), ATC_STR_RAT_MAX
(deg/s), ATC_ACCEL_MAX (m/s/s), RTL_SPEED, MIS_DONE_BEHAVE (0 hold, 1 loiter, 2 acro, 3 manual),
FS_GCS_ENABLE, FS_TIMEOUT and the failsafe actions (Rover 4.6 has no FENCE_ALT_*: its fence is
horizontal). Command: DO_SET_REVERSE (drive backwards).
"""

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.autopilot.settings import DISARM, Settings
from gcsd.vehicle.autopilot.settings import Behaviour as B
from gcsd.vehicle.sim import GroundDynamics, Limits
from gcsd.vehicle.types import commands, common, motors, prearm
from gcsd.vehicle.types.base import VehicleType, modes_named, stream_rates
from gcsd.vehicle.types.modes import mode_mapping

_modes = mode_mapping("rover")
_by_name = {v: k for k, v in _modes.items()}

# ArduRover 4.6's parameters this module's settings() reads (all of them: params/data/rover.tsv).
PARAMS = (
    "CRUISE_SPEED", "CRUISE_THROTTLE", "WP_SPEED", "WP_RADIUS", "LOIT_RADIUS", "ATC_STR_RAT_MAX", "ATC_ACCEL_MAX",
    "RTL_SPEED", "MIS_DONE_BEHAVE", "FS_GCS_ENABLE", "FS_TIMEOUT", "FS_THR_ENABLE", "FS_ACTION",
) + common.FAILSAFE_PARAMS

GCS_ACTIONS = {1: "RTL", 2: "HOLD"}
BATTERY_ACTIONS = {1: "RTL", 2: "HOLD", 3: "RTL", 4: "HOLD", 5: DISARM}
FENCE_ACTIONS = {1: "RTL", 2: "HOLD", 3: "RTL", 4: "HOLD"}
MISSION_END = {0: None, 1: "LOITER", 2: "ACRO", 3: "MANUAL"}
# FS_ACTION (with FS_THR_ENABLE on): 0 nothing, 1 RTL, 2 HOLD, 3 SmartRTL or RTL, 4 SmartRTL or
# HOLD, 5 terminate (gcsd: disarm)
RADIO_ACTIONS = {1: "RTL", 2: "HOLD", 3: "SMART_RTL", 4: "SMART_RTL", 5: DISARM}


def settings(get) -> Settings:
    cruise = float(get("CRUISE_SPEED"))
    wp_speed = float(get("WP_SPEED")) or cruise
    limits = Limits(
        cruise_speed_ms=wp_speed, max_speed_ms=max(cruise, wp_speed) * 1.5, accel_ms2=float(get("ATC_ACCEL_MAX")) or 1.0,
        yaw_rate_dps=float(get("ATC_STR_RAT_MAX")) or 120.0, wp_radius_m=float(get("WP_RADIUS")),
        loiter_radius_m=float(get("LOIT_RADIUS")), hover_throttle=float(get("CRUISE_THROTTLE")) / 100.0,
        cruise_current_a=4.0, angle_max_deg=45.0,
    )
    return Settings(
        limits=limits, rtl_alt_m=-1.0, rtl_lands=False, rtl_loiter_s=0.0, rtl_speed_ms=float(get("RTL_SPEED")) or None,
        mission_end=MISSION_END.get(int(get("MIS_DONE_BEHAVE"))), ignore_alt_for_waypoints=True,
        gcs_failsafe=common.action(GCS_ACTIONS, get("FS_GCS_ENABLE")), gcs_timeout_s=float(get("FS_TIMEOUT")),
        radio_failsafe=common.action(RADIO_ACTIONS, get("FS_ACTION")) if get("FS_THR_ENABLE") else None,
        battery_low=common.action(BATTERY_ACTIONS, get("BATT_FS_LOW_ACT")),
        battery_critical=common.action(BATTERY_ACTIONS, get("BATT_FS_CRT_ACT")),
        fence_action=common.action(FENCE_ACTIONS, get("FENCE_ACTION")),
    )


ROVER = VehicleType(
    name="rover",
    firmware="ArduRover",
    motor_pwm=motors.rover_throttle_pwm,
    mav_type=M.MAV_TYPE_GROUND_ROVER,
    modes=_modes,
    initial_mode=_by_name["MANUAL"],
    capabilities=(
        M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
        | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    ),
    guided_modes=frozenset({_by_name[n] for n in ("GUIDED", "AUTO", "RTL", "SMART_RTL")}),
    manual_modes=frozenset({_by_name["MANUAL"]}),
    behaviours=modes_named(
        _modes, MANUAL=B.MANUAL, ACRO=B.MANUAL, LEARNING=B.MANUAL, STEERING=B.MANUAL, SIMPLE=B.MANUAL,
        HOLD=B.HOLD, LOITER=B.HOLD, FOLLOW=B.HOLD, DOCK=B.HOLD, CIRCLE=B.CIRCLE, AUTO=B.AUTO, RTL=B.RTL,
        SMART_RTL=B.RTL, GUIDED=B.GUIDED, INITIALISING=B.IDLE,
    ),
    dynamics=GroundDynamics,
    params=PARAMS,
    settings=settings,
    prearm_checks=prearm.DRIVING_CHECKS,
    commands=commands.ROVER_COMMANDS,
    radio_trim_sticks=(0,),  # trim_radio: steering
    ardupilot_stream_rates=stream_rates(1, 1, 1, 1, 1, 1, 1, 1, 10, 0),
)
