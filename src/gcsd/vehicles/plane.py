"""ArduPlane: MAV_TYPE_FIXED_WING, ArduPlane's modes, a fixed wing that must keep flying.

Parameters (4.5+ names): AIRSPEED_CRUISE, AIRSPEED_MIN, AIRSPEED_MAX (m/s), TRIM_THROTTLE,
LIM_ROLL_CD, LIM_PITCH_MAX, LIM_PITCH_MIN (cdeg), WP_RADIUS, WP_LOITER_RAD, RTL_RADIUS (m),
ALT_HOLD_RTL (cm), TKOFF_ALT (m), TECS_CLMB_MAX, TECS_SINK_MAX (m/s), LAND_DISARMDELAY (s),
FS_GCS_ENABL, FS_LONG_TIMEOUT, plus the shared groups. Commands: NAV_TAKEOFF switches to
TAKEOFF mode with its altitude; DO_LAND_START jumps to the mission's landing sequence. A
mission ends in RTL, as ArduPlane's does.
"""

from pymavlink.dialects.v20 import ardupilotmega as M

from ..autopilot.settings import DISARM, Settings
from ..autopilot.settings import Behaviour as B
from ..params.store import INT8, INT16, INT32, REAL32
from ..params.store import ParamDef as P
from ..sim import FixedWingDynamics, Limits
from . import commands, common, prearm
from .base import VehicleType, modes_named, stream_rates
from .modes import mode_mapping

_modes = mode_mapping("apm")
_by_name = {v: k for k, v in _modes.items()}

PARAMS = (
    P("AIRSPEED_CRUISE", REAL32, 15.0, 5.0, 100.0, "m/s", "Cruise airspeed"),
    P("AIRSPEED_MIN", INT16, 9, 5, 100, "m/s", "Minimum airspeed"),
    P("AIRSPEED_MAX", INT16, 22, 5, 100, "m/s", "Maximum airspeed"),
    P("TRIM_THROTTLE", INT8, 45, 0, 100, "%", "Cruise throttle"),
    P("LIM_ROLL_CD", INT16, 4500, 0, 9000, "cdeg", "Maximum bank angle"),
    P("LIM_PITCH_MAX", INT16, 2000, 0, 9000, "cdeg", "Maximum pitch up"),
    P("LIM_PITCH_MIN", INT16, -2500, -9000, 0, "cdeg", "Maximum pitch down"),
    P("WP_RADIUS", INT16, 90, 1, 32767, "m", "A waypoint is reached within this distance"),
    P("WP_LOITER_RAD", INT16, 60, -32767, 32767, "m", "Loiter radius (negative: counter-clockwise)"),
    P("RTL_RADIUS", INT16, 0, -32767, 32767, "m", "Loiter radius at home after RTL (0: WP_LOITER_RAD)"),
    P("ALT_HOLD_RTL", INT32, 10000, -1, 32767000, "cm", "RTL altitude above home (-1: the current altitude)"),
    P("TKOFF_ALT", INT16, 50, 0, 32767, "m", "Takeoff altitude above home"),
    P("TECS_CLMB_MAX", REAL32, 5.0, 0.1, 20.0, "m/s", "Maximum climb rate"),
    P("TECS_SINK_MAX", REAL32, 5.0, 0.0, 20.0, "m/s", "Maximum sink rate"),
    P("LAND_DISARMDELAY", INT8, 20, 0, 127, "s", "Disarm this long after landing"),
    P("FS_GCS_ENABL", INT8, 0, 0, 2, "", "GCS failsafe: 0 off, 1 heartbeat loss, 2 also RC loss"),
    P("FS_LONG_TIMEOUT", REAL32, 5.0, 1.0, 300.0, "s", "GCS heartbeat loss before the failsafe (RTL)"),
) + common.fence_params() + common.rally_params() + common.battery_failsafe_params(0, 0) \
    + common.rc_override_params()

BATTERY_ACTIONS = {1: "RTL", 2: "RTL", 3: DISARM, 4: "RTL", 5: "RTL", 6: "LOITER"}
FENCE_ACTIONS = {1: "RTL", 2: "GUIDED", 3: "GUIDED", 4: "RTL", 5: "LOITER", 6: "LOITER"}


def settings(get) -> Settings:
    loiter = float(get("WP_LOITER_RAD"))
    rtl_radius = float(get("RTL_RADIUS")) or loiter
    limits = Limits(
        cruise_speed_ms=float(get("AIRSPEED_CRUISE")), max_speed_ms=float(get("AIRSPEED_MAX")), accel_ms2=2.0,
        climb_ms=float(get("TECS_CLMB_MAX")), descent_ms=float(get("TECS_SINK_MAX")), land_speed_ms=1.0,
        yaw_rate_dps=30.0, angle_max_deg=float(get("LIM_ROLL_CD")) / 100.0, wp_radius_m=float(get("WP_RADIUS")),
        loiter_radius_m=abs(loiter) or 60.0, min_airspeed_ms=float(get("AIRSPEED_MIN")),
        max_airspeed_ms=float(get("AIRSPEED_MAX")), pitch_max_deg=float(get("LIM_PITCH_MAX")) / 100.0,
        pitch_min_deg=float(get("LIM_PITCH_MIN")) / 100.0, hover_throttle=float(get("TRIM_THROTTLE")) / 100.0,
        cruise_current_a=10.0,
    )
    rtl_alt = float(get("ALT_HOLD_RTL"))
    return Settings(
        limits=limits, fixed_wing=True, rtl_alt_m=rtl_alt / 100.0 if rtl_alt >= 0 else -1.0, rtl_lands=False,
        rtl_loiter_s=0.0, takeoff_alt_m=float(get("TKOFF_ALT")),
        land_disarm_delay_s=float(get("LAND_DISARMDELAY")), mission_end="RTL",
        gcs_failsafe="RTL" if get("FS_GCS_ENABL") else None, gcs_timeout_s=float(get("FS_LONG_TIMEOUT")),
        battery_low=common.action(BATTERY_ACTIONS, get("BATT_FS_LOW_ACT")),
        battery_critical=common.action(BATTERY_ACTIONS, get("BATT_FS_CRT_ACT")),
        fence_action=common.action(FENCE_ACTIONS, get("FENCE_ACTION")),
        circle_radius_m=abs(loiter) or 60.0, extra={"rtl_radius_m": abs(rtl_radius) or 60.0},
    )


PLANE = VehicleType(
    name="plane",
    mav_type=M.MAV_TYPE_FIXED_WING,
    modes=_modes,
    initial_mode=_by_name["MANUAL"],
    capabilities=M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT,
    guided_modes=frozenset({_by_name[n] for n in ("GUIDED", "AUTO", "RTL", "LOITER", "TAKEOFF")}),
    manual_modes=frozenset({_by_name["MANUAL"]}),
    behaviours=modes_named(
        _modes, MANUAL=B.MANUAL, STABILIZE=B.MANUAL, TRAINING=B.MANUAL, ACRO=B.MANUAL, FBWA=B.MANUAL,
        FBWB=B.MANUAL, CRUISE=B.MANUAL, AUTOTUNE=B.MANUAL, AUTO=B.AUTO, RTL=B.RTL, LOITER=B.HOLD,
        TAKEOFF=B.TAKEOFF, GUIDED=B.GUIDED, CIRCLE=B.CIRCLE, INITIALISING=B.IDLE, THERMAL=B.HOLD,
        QSTABILIZE=B.MANUAL, QHOVER=B.MANUAL, QLOITER=B.HOLD, QLAND=B.LAND, QRTL=B.RTL, QAUTOTUNE=B.HOLD,
        QACRO=B.MANUAL, LOITERALTQLAND=B.LAND, AUTOLAND=B.LAND, AVOID_ADSB=B.HOLD,
    ),
    dynamics=FixedWingDynamics,
    params=PARAMS,
    settings=settings,
    prearm_checks=prearm.FLYING_CHECKS,
    commands={
        M.MAV_CMD_NAV_TAKEOFF: commands.takeoff_mode,
        M.MAV_CMD_DO_LAND_START: commands.land_start,
    },
    ardupilot_stream_rates=stream_rates(1, 1, 1, 1, 1, 1, 1, 1, 10, 5),
)
