"""ArduPlane: MAV_TYPE_FIXED_WING, ArduPlane's modes, a fixed wing that must keep flying.

Parameters: ArduPlane 4.6's set (params/data/plane.tsv). Its settings read AIRSPEED_CRUISE,
AIRSPEED_MIN, AIRSPEED_MAX (m/s), TRIM_THROTTLE, ROLL_LIMIT_DEG, PTCH_LIM_MAX_DEG, PTCH_LIM_MIN_DEG
(deg), WP_RADIUS, WP_LOITER_RAD, RTL_RADIUS, RTL_ALTITUDE (m, -1: the current altitude), TKOFF_ALT
(m), TECS_CLMB_MAX, TECS_SINK_MAX (m/s), LAND_DISARMDELAY (s), FS_GCS_ENABL, FS_LONG_TIMEOUT and
the failsafe actions. Commands: NAV_TAKEOFF switches to
TAKEOFF mode with its altitude; DO_LAND_START jumps to the mission's landing sequence. A
mission ends in RTL, as ArduPlane's does.
"""

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.autopilot.settings import DISARM, Settings
from gcsd.vehicle.autopilot.settings import Behaviour as B
from gcsd.vehicle.sim import FixedWingDynamics, Limits
from gcsd.vehicle.types import commands, common, motors, prearm
from gcsd.vehicle.types.base import VehicleType, modes_named, stream_rates
from gcsd.vehicle.types.modes import mode_mapping

_modes = mode_mapping("apm")
_by_name = {v: k for k, v in _modes.items()}

# ArduPlane 4.6's parameters this module's settings() reads (all of them: params/data/plane.tsv).
PARAMS = (
    "AIRSPEED_CRUISE", "AIRSPEED_MIN", "AIRSPEED_MAX", "TRIM_THROTTLE", "ROLL_LIMIT_DEG", "PTCH_LIM_MAX_DEG",
    "PTCH_LIM_MIN_DEG", "WP_RADIUS", "WP_LOITER_RAD", "RTL_RADIUS", "RTL_ALTITUDE", "TKOFF_ALT", "TECS_CLMB_MAX",
    "TECS_SINK_MAX", "LAND_DISARMDELAY", "FS_GCS_ENABL", "FS_LONG_TIMEOUT", "THR_FAILSAFE", "FS_LONG_ACTN",
) + common.FAILSAFE_PARAMS

BATTERY_ACTIONS = {1: "RTL", 2: "RTL", 3: DISARM, 4: "RTL", 5: "RTL", 6: "LOITER"}
FENCE_ACTIONS = {1: "RTL", 2: "GUIDED", 3: "GUIDED", 4: "RTL", 5: "LOITER", 6: "LOITER"}
# THR_FAILSAFE 1 (2: no failsafe action): FS_LONG_ACTN 0 continue (gcsd: RTL), 1 RTL, 2 glide
# (FBWA), 3 parachute (gcsd: RTL), 4 AUTO. The short failsafe (FS_SHORT_ACTN after
# FS_SHORT_TIMEOUT) is not modelled: the long action at once.
RADIO_ACTIONS = {0: "RTL", 1: "RTL", 2: "FBWA", 3: "RTL", 4: "AUTO"}


def settings(get) -> Settings:
    loiter = float(get("WP_LOITER_RAD"))
    rtl_radius = float(get("RTL_RADIUS")) or loiter
    limits = Limits(
        cruise_speed_ms=float(get("AIRSPEED_CRUISE")), max_speed_ms=float(get("AIRSPEED_MAX")), accel_ms2=2.0,
        climb_ms=float(get("TECS_CLMB_MAX")), descent_ms=float(get("TECS_SINK_MAX")), land_speed_ms=1.0,
        yaw_rate_dps=30.0, angle_max_deg=float(get("ROLL_LIMIT_DEG")), wp_radius_m=float(get("WP_RADIUS")),
        loiter_radius_m=abs(loiter) or 60.0, min_airspeed_ms=float(get("AIRSPEED_MIN")),
        max_airspeed_ms=float(get("AIRSPEED_MAX")), pitch_max_deg=float(get("PTCH_LIM_MAX_DEG")),
        pitch_min_deg=float(get("PTCH_LIM_MIN_DEG")), hover_throttle=float(get("TRIM_THROTTLE")) / 100.0,
        cruise_current_a=10.0,
    )
    rtl_alt = float(get("RTL_ALTITUDE"))
    return Settings(
        limits=limits, fixed_wing=True, rtl_alt_m=rtl_alt if rtl_alt >= 0 else -1.0, rtl_lands=False,
        rtl_loiter_s=0.0, takeoff_alt_m=float(get("TKOFF_ALT")),
        land_disarm_delay_s=float(get("LAND_DISARMDELAY")), mission_end="RTL",
        gcs_failsafe="RTL" if get("FS_GCS_ENABL") else None, gcs_timeout_s=float(get("FS_LONG_TIMEOUT")),
        radio_failsafe=common.action(RADIO_ACTIONS, get("FS_LONG_ACTN")) if get("THR_FAILSAFE") == 1 else None,
        battery_low=common.action(BATTERY_ACTIONS, get("BATT_FS_LOW_ACT")),
        battery_critical=common.action(BATTERY_ACTIONS, get("BATT_FS_CRT_ACT")),
        fence_action=common.action(FENCE_ACTIONS, get("FENCE_ACTION")),
        circle_radius_m=abs(loiter) or 60.0, extra={"rtl_radius_m": abs(rtl_radius) or 60.0},
    )


PLANE = VehicleType(
    name="plane",
    firmware="ArduPlane",
    motor_pwm=motors.plane_throttle_pwm,
    mav_type=M.MAV_TYPE_FIXED_WING,
    modes=_modes,
    initial_mode=_by_name["MANUAL"],
    capabilities=M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT | M.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT,
    guided_modes=frozenset({_by_name[n] for n in ("GUIDED", "AUTO", "RTL", "LOITER", "TAKEOFF")}),
    manual_modes=frozenset(),  # ArduPlane's HEARTBEAT has STABILIZE_ENABLED even in MANUAL (base_mode 81 on SITL)
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
    commands=commands.PLANE_COMMANDS,
    radio_trim_sticks=(0, 1, 3),  # trim_radio: roll, pitch, yaw
    ardupilot_stream_rates=stream_rates(1, 1, 1, 1, 1, 1, 1, 1, 10, 5),
)
