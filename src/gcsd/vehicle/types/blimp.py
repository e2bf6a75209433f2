"""Blimp: MAV_TYPE_AIRSHIP, Blimp's modes, a slow airship that drifts and loiters.

Parameters: Blimp's (params/data/blimp.tsv: the Blimp-4.7 metadata's names with the captured
vehicles' types and values). Its settings read MAX_VEL_XY, MAX_VEL_Z (m/s), MAX_VEL_YAW (deg/s),
MAX_POS_XY (m: the loiter tolerance inside which it lets the wind carry it), FS_GCS_ENABLE,
FS_GCS_TIMEOUT and the failsafe actions; Blimp has no waypoint radius parameter (2 m).
Commands: NAV_TAKEOFF in VELOCITY or LOITER (armed, on the ground).
"""

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.autopilot.settings import DISARM, Settings
from gcsd.vehicle.autopilot.settings import Behaviour as B
from gcsd.vehicle.sim import BlimpDynamics, Limits
from gcsd.vehicle.types import commands, common, prearm
from gcsd.vehicle.types.base import VehicleType, modes_named, stream_rates
from gcsd.vehicle.types.modes import mode_mapping

_modes = mode_mapping("blimp")
_by_name = {v: k for k, v in _modes.items()}

# Blimp's parameters this module's settings() reads (all of them: params/data/blimp.tsv).
PARAMS = ("MAX_VEL_XY", "MAX_VEL_Z", "MAX_VEL_YAW", "MAX_POS_XY", "FS_GCS_ENABLE", "FS_GCS_TIMEOUT") \
    + common.FAILSAFE_PARAMS
WP_RADIUS_M = 2.0  # Blimp has no waypoint radius parameter

GCS_ACTIONS = {1: "LAND", 2: "RTL"}
BATTERY_ACTIONS = {1: "LAND", 2: "RTL", 3: DISARM}
FENCE_ACTIONS = {1: "RTL", 2: "LAND", 3: "HOLD"}


def settings(get) -> Settings:
    xy, z = float(get("MAX_VEL_XY")), float(get("MAX_VEL_Z"))
    limits = Limits(
        cruise_speed_ms=xy, max_speed_ms=xy, accel_ms2=0.3, climb_ms=z, descent_ms=z, land_speed_ms=z * 0.5,
        land_alt_low_m=3.0, yaw_rate_dps=float(get("MAX_VEL_YAW")), angle_max_deg=5.0,
        wp_radius_m=WP_RADIUS_M, loiter_radius_m=float(get("MAX_POS_XY")), hover_throttle=0.2,
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
    firmware="Blimp",
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
