"""Commands whose meaning differs per vehicle type: `handler(ctx, request) -> MAV_RESULT`.

A vehicle type lists the ones it supports in `VehicleType.commands` (COPTER_COMMANDS etc. at
the end); that table wins over the generic services' handlers (compose.py registers it
last), so a vehicle type can also say `unsupported` (ArduPilot's vehicle code has no case for
the command: CONDITION_YAW on a plane, landing gear on a rover) or `failed`. Which answer each
gets follows ArduPilot SITL's (../shared/ardupilot/*-probe.json; docs/commands.md).

- takeoff_in_guided (copter, blimp): NAV_TAKEOFF param7 = altitude above home; needs GUIDED,
  armed, on the ground (else FAILED), as ArduCopter's do_user_takeoff.
- takeoff_mode (plane): NAV_TAKEOFF switches to TAKEOFF mode; param7 > 0 sets its altitude.
- land_start (plane): DO_LAND_START jumps the mission to its DO_LAND_START marker and flies on.
- motor_test (copter): DO_MOTOR_TEST param1 motor, param2 throttle type, param3 throttle,
  param4 seconds, with ArduCopter's checks (disarmed, landed, safety off, RC calibrated).
- set_reverse (rover): DO_SET_REVERSE param1 1 drives backwards.
- the rest (condition_yaw_any_mode, change_speed*, flight_termination, return_path_start,
  solo buttons, plane's autotune/go-around/guided changes...) say ArduPilot's rule each.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.autopilot.settings import Behaviour
from gcsd.vehicle.types import prearm
from gcsd.wire.msgids import ACCEPTED, DENIED, FAILED

UNSUPPORTED = M.MAV_RESULT_UNSUPPORTED


def takeoff_in_guided(ctx, req) -> int:
    alt = req.z
    if not math.isfinite(alt) or alt <= 0:
        alt = ctx.autopilot.settings.takeoff_alt_m
    return ACCEPTED if ctx.autopilot.takeoff(alt) else FAILED


def takeoff_mode(ctx, req) -> int:
    if math.isfinite(req.z) and req.z > 0:
        ctx.autopilot.set_takeoff_alt(req.z)
    return ACCEPTED if ctx.autopilot.set_mode("TAKEOFF") else FAILED


def land_start(ctx, req) -> int:
    items = ctx.plans.mission.stored()
    for seq, item in enumerate(items):
        if item.command == M.MAV_CMD_DO_LAND_START:
            ctx.plans.mission.set_current(seq)
            return ACCEPTED if ctx.autopilot.start_mission(seq) else FAILED
    return FAILED


MOTOR_TEST_MAX_S = 30.0  # ArduCopter's MOTOR_TEST_TIMEOUT_MS_MAX
THROTTLE_PERCENT, THROTTLE_PWM = M.MOTOR_TEST_THROTTLE_PERCENT, M.MOTOR_TEST_THROTTLE_PWM


def _motor_pwm_range(ctx) -> tuple[float, float]:
    """ArduCopter's get_pwm_output_min/max: MOT_PWM_MIN/MAX, or RC3_MIN/MAX where those are 0."""
    p = ctx.params
    lo = p.get("MOT_PWM_MIN") if "MOT_PWM_MIN" in p else 0
    hi = p.get("MOT_PWM_MAX") if "MOT_PWM_MAX" in p else 0
    if not lo or not hi:
        lo, hi = p.get("RC3_MIN"), p.get("RC3_MAX")
    return float(lo), float(hi)


def motor_test(ctx, req) -> int:
    """ArduCopter's mavlink_motor_test_start: param1 motor (the output whose SERVOn_FUNCTION is that
    motor), param2 throttle type (0 percent of MOT_PWM_MIN..MAX, 1 PWM), param3 throttle, param4
    seconds (at most 30). Refused (FAILED, with
    ArduPilot's STATUSTEXT) when armed, not landed, with the safety switch on or, for a percentage,
    with RC not calibrated; a motor beyond the frame's outputs or a throttle out of range: FAILED."""
    if ctx.state.armed:
        ctx.text(M.MAV_SEVERITY_CRITICAL, "Must be disarmed for motor test")
        return FAILED
    reasons = [("Motor Test: vehicle not landed", not ctx.state.on_ground),
               ("Motor Test: Safety switch", "Hardware safety switch" in prearm.safety_switch(ctx)),
               ("Motor Test: RC not calibrated", req.param2 != THROTTLE_PWM and bool(prearm.rc_calibration(ctx)))]
    for text, failing in reasons:
        if failing:
            ctx.text(M.MAV_SEVERITY_CRITICAL, text)
            return FAILED
    motor = int(req.param1) if math.isfinite(req.param1) else 0
    get = ctx.params.get
    outputs = {int(get(f"SERVO{n}_FUNCTION")) - 32: n for n in range(1, 17) if f"SERVO{n}_FUNCTION" in ctx.params
               and 33 <= get(f"SERVO{n}_FUNCTION") <= 40}  # motor number -> output
    if motor not in outputs:
        return FAILED
    output = outputs[motor]
    lo, hi = _motor_pwm_range(ctx)
    if req.param2 == THROTTLE_PWM and lo <= req.param3 <= hi:
        pwm = req.param3
    elif req.param2 == THROTTLE_PERCENT and 0 <= req.param3 <= 100:
        pwm = lo + (hi - lo) * req.param3 / 100.0
    else:
        return FAILED
    servo_lo, servo_hi = get(f"SERVO{output}_MIN"), get(f"SERVO{output}_MAX")
    percent_of_servo = 100.0 * (pwm - servo_lo) / max(servo_hi - servo_lo, 1)  # what outputs.motor_test takes
    seconds = max(0.0, min(req.param4, MOTOR_TEST_MAX_S)) if math.isfinite(req.param4) else 0.0
    ctx.text(M.MAV_SEVERITY_INFO, "starting motor test")
    ctx.autopilot.motor_test(output, percent_of_servo, seconds)
    return ACCEPTED


def set_reverse(ctx, req) -> int:
    ctx.autopilot.reversed = req.param1 >= 1
    return ACCEPTED


# --- per-vehicle answers ArduPilot gives (../shared/ardupilot/*-probe.json; docs/commands.md) ---


def unsupported(ctx, req) -> int:
    """The vehicle type does not handle this command (ArduPilot's vehicle code has no case for it)."""
    return UNSUPPORTED


def failed(ctx, req) -> int:
    """The vehicle type has the feature compiled in but nothing to do it with (no sprayer on a plane...)."""
    return FAILED


def condition_yaw_any_mode(ctx, req) -> int:
    """ArduCopter: CONDITION_YAW sets the auto-yaw target in any mode (angle 0..360, param4 0 absolute
    or 1 relative), else FAILED."""
    if not 0 <= req.param1 <= 360 or req.param4 not in (0, 1):
        return FAILED
    ctx.autopilot.condition_yaw(req.param1, req.param2, req.param3, req.param4)
    return ACCEPTED


def change_speed_copter(ctx, req) -> int:
    """ArduCopter: a speed that is not positive is DENIED; else the current mode takes it or FAILED."""
    if not req.param2 > 0:
        return DENIED
    return ACCEPTED if ctx.autopilot.change_speed(req.param2) else FAILED


def change_speed(ctx, req) -> int:
    """ArduPlane / Rover: no positive speed, or a mode that cannot take one: FAILED."""
    if not req.param2 > 0:
        return FAILED
    return ACCEPTED if ctx.autopilot.change_speed(req.param2) else FAILED


def flight_termination(ctx, req) -> int:
    """param1 > 0.5 terminates (the motors stop: disarmed); anything else is FAILED, as ArduPilot."""
    if req.param1 > 0.5:
        ctx.autopilot.disarm("flight termination")
        return ACCEPTED
    return FAILED


def _jump_to(ctx, command: int) -> int:
    items = ctx.plans.mission.stored()
    for seq, item in enumerate(items):
        if item.command == command:
            ctx.plans.mission.set_current(seq)
            return ACCEPTED if ctx.autopilot.start_mission(seq) else FAILED
    return FAILED


def return_path_start(ctx, req) -> int:
    """DO_RETURN_PATH_START: continue the mission from its DO_RETURN_PATH_START item (none: FAILED)."""
    return _jump_to(ctx, M.MAV_CMD_DO_RETURN_PATH_START)


def land_mode(ctx, req) -> int:
    """NAV_VTOL_LAND on a copter is NAV_LAND: LAND mode."""
    number = ctx.vehicle.mode_number("LAND")
    return ACCEPTED if number is not None and ctx.control.set_mode(number) else FAILED


def solo_fly_click(ctx, req) -> int:
    """ArduCopter's Solo "Fly" button: LOITER (ALT_HOLD without a position), always ACCEPTED."""
    for name in ("LOITER", "ALT_HOLD"):
        number = ctx.vehicle.mode_number(name)
        if number is not None and ctx.control.set_mode(number):
            break
    return ACCEPTED


def solo_fly_hold(ctx, req) -> int:
    """Solo "Fly" held: arm when disarmed (pre-arm checks apply), take off when armed and landed."""
    if not ctx.state.armed:
        ctx.control.arm(forced=False)
    elif ctx.state.on_ground:
        ctx.autopilot.takeoff(req.param1 if req.param1 > 0 else ctx.autopilot.settings.takeoff_alt_m)
    return ACCEPTED


def solo_pause_click(ctx, req) -> int:
    """Solo "Pause": BRAKE when flying; always ACCEPTED."""
    if ctx.state.armed and not ctx.state.on_ground:
        number = ctx.vehicle.mode_number("BRAKE")
        if number is not None:
            ctx.control.set_mode(number)
    return ACCEPTED


def sprayer(ctx, req) -> int:
    """DO_SPRAYER (AC_Sprayer): param1 1 on, 0 off; ACCEPTED as ArduPilot (it only sprays with
    SPRAY_ENABLE set and the vehicle moving)."""
    return ACCEPTED


def autotune_enable(ctx, req) -> int:
    """ArduPlane DO_AUTOTUNE_ENABLE: 0 turns autotune off (nothing runs: ACCEPTED); the simulation has
    no autotuner, so turning it on is FAILED."""
    return ACCEPTED if req.param1 == 0 else FAILED


def go_around(ctx, req) -> int:
    """ArduPlane DO_GO_AROUND: only while landing (then RTL); else FAILED."""
    if not ctx.state.armed or ctx.state.on_ground or ctx.autopilot.behaviour != Behaviour.LAND:
        return FAILED
    return ACCEPTED if ctx.autopilot.set_mode("RTL") else FAILED


def _in_guided(ctx) -> bool:
    return ctx.autopilot.in_guided()


def guided_change_speed(ctx, req) -> int:
    """ArduPlane GUIDED_CHANGE_SPEED: GUIDED only (param2 m/s)."""
    if not _in_guided(ctx) or not req.param2 > 0:
        return FAILED
    return ACCEPTED if ctx.autopilot.change_speed(req.param2) else FAILED


def guided_change_altitude(ctx, req) -> int:
    """ArduPlane GUIDED_CHANGE_ALTITUDE: GUIDED only (param3 m above home)."""
    if not _in_guided(ctx):
        return FAILED
    s = ctx.state
    return ACCEPTED if ctx.autopilot.change_altitude(s.home_alt_m + req.param3) else FAILED


def set_hagl(ctx, req) -> int:
    """ArduPlane SET_HAGL: an external height above ground for the flare; the simulation knows its
    height, so the estimate is taken (ACCEPTED) and not needed."""
    return ACCEPTED


# --- each vehicle type's table (it wins over the generic services' handlers) -------------------
COPTER_COMMANDS = {
    M.MAV_CMD_NAV_TAKEOFF: takeoff_in_guided, M.MAV_CMD_NAV_VTOL_TAKEOFF: takeoff_in_guided,
    M.MAV_CMD_NAV_VTOL_LAND: land_mode, M.MAV_CMD_DO_MOTOR_TEST: motor_test,
    M.MAV_CMD_CONDITION_YAW: condition_yaw_any_mode, M.MAV_CMD_DO_CHANGE_SPEED: change_speed_copter,
    M.MAV_CMD_DO_CHANGE_ALTITUDE: unsupported, M.MAV_CMD_DO_FLIGHTTERMINATION: flight_termination,
    M.MAV_CMD_DO_LAND_START: land_start, M.MAV_CMD_DO_RETURN_PATH_START: return_path_start,
    M.MAV_CMD_SOLO_BTN_FLY_CLICK: solo_fly_click, M.MAV_CMD_SOLO_BTN_FLY_HOLD: solo_fly_hold,
    M.MAV_CMD_SOLO_BTN_PAUSE_CLICK: solo_pause_click, M.MAV_CMD_DO_SPRAYER: sprayer,
    M.MAV_CMD_DO_WINCH: failed,  # AP_Winch is a copter library; no winch is simulated (WINCH_TYPE 0)
}
PLANE_COMMANDS = {
    M.MAV_CMD_NAV_TAKEOFF: takeoff_mode, M.MAV_CMD_DO_LAND_START: land_start,
    M.MAV_CMD_CONDITION_YAW: unsupported, M.MAV_CMD_DO_PAUSE_CONTINUE: unsupported,
    M.MAV_CMD_DO_CHANGE_SPEED: change_speed, M.MAV_CMD_DO_FLIGHTTERMINATION: flight_termination,
    M.MAV_CMD_DO_RETURN_PATH_START: return_path_start, M.MAV_CMD_DO_AUTOTUNE_ENABLE: autotune_enable,
    M.MAV_CMD_DO_ENGINE_CONTROL: failed, M.MAV_CMD_DO_VTOL_TRANSITION: failed, M.MAV_CMD_DO_GO_AROUND: go_around,
    M.MAV_CMD_GUIDED_CHANGE_SPEED: guided_change_speed, M.MAV_CMD_GUIDED_CHANGE_ALTITUDE: guided_change_altitude,
    M.MAV_CMD_GUIDED_CHANGE_HEADING: failed, M.MAV_CMD_SET_HAGL: set_hagl, M.MAV_CMD_DO_SPRAYER: failed,
}
ROVER_COMMANDS = {
    M.MAV_CMD_DO_SET_REVERSE: set_reverse, M.MAV_CMD_CONDITION_YAW: unsupported,
    M.MAV_CMD_DO_PAUSE_CONTINUE: unsupported, M.MAV_CMD_DO_FLIGHTTERMINATION: unsupported,
    M.MAV_CMD_NAV_LOITER_UNLIM: unsupported, M.MAV_CMD_AIRFRAME_CONFIGURATION: unsupported,
    M.MAV_CMD_DO_PARACHUTE: unsupported, M.MAV_CMD_DO_CHANGE_SPEED: change_speed, M.MAV_CMD_DO_SPRAYER: sprayer,
}
