"""Motor and throttle outputs of SERVO_OUTPUT_RAW as ArduPilot writes them.

A multicopter (AP_MotorsMulticopter):

FRAME_CLASS decides how many motors the frame has (gcsd.vehicle.types.firmware.FRAME_CLASSES: QUAD 4,
HEXA 6, OCTA 8, Y6 6, TRI 3, ...). Output n drives motor m when SERVOn_FUNCTION is Motor m (33..40,
82..85 for 9..12), or when it is 0 and n is one of the frame's motors (ArduPilot assigns the
default channels of a new frame at its next start). A motor function the frame does not use
outputs 0. The PWM range is MOT_PWM_MIN..MOT_PWM_MAX (0: RC3_MIN..RC3_MAX, as
get_pwm_output_min/max): disarmed the minimum; armed on the ground MOT_SPIN_ARM of the range
(ground idle); in the air MOT_SPIN_MIN..MOT_SPIN_MAX scaled by the simulated throttle.

A plane or a rover: an output whose SERVOn_FUNCTION is Throttle (70, or 73/74 left/right) follows
the simulated throttle from SERVOn_MIN (plane; disarmed: MIN) or from SERVOn_TRIM (rover, whose
throttle is centred for reverse; disarmed: TRIM) to SERVOn_MAX, reversed with SERVOn_REVERSED.
"""

from __future__ import annotations

from gcsd.vehicle.types.firmware import motor_count

MOTOR_FUNCTIONS = {**{33 + i: i + 1 for i in range(8)}, **{82 + i: 9 + i for i in range(4)}}


def pwm_range(get) -> tuple[float, float]:
    lo, hi = get("MOT_PWM_MIN"), get("MOT_PWM_MAX")
    if lo > 0 and hi > lo:
        return lo, hi
    return get("RC3_MIN"), get("RC3_MAX")


def motor_of_output(get, n: int) -> int | None:
    function = int(get(f"SERVO{n}_FUNCTION"))
    if function in MOTOR_FUNCTIONS:
        return MOTOR_FUNCTIONS[function]
    if function == 0 and n <= motor_count(get):
        return n
    return None


def copter_motor_pwm(ctx, n: int) -> int | None:
    """SERVO_OUTPUT_RAW for output n if it is a motor output (None: not a motor)."""
    get = ctx.params.clamped
    motor = motor_of_output(get, n)
    if motor is None:
        return None
    if motor > motor_count(get):
        return 0
    lo, hi = pwm_range(get)
    s = ctx.state
    if not s.armed:
        return int(lo)
    throttle = max(0.0, min(1.0, s.throttle_pct / 100.0))
    if s.on_ground:  # spooled to ground idle (the simulation has no spool-up on the ground)
        thrust = get("MOT_SPIN_ARM")
    else:
        thrust = get("MOT_SPIN_MIN") + (get("MOT_SPIN_MAX") - get("MOT_SPIN_MIN")) * throttle
    return int(lo + (hi - lo) * thrust)


THROTTLE_FUNCTIONS = frozenset({70, 73, 74})


def _throttle_pwm(ctx, n: int, centred: bool) -> int | None:
    get = ctx.params.clamped
    if int(get(f"SERVO{n}_FUNCTION")) not in THROTTLE_FUNCTIONS:
        return None
    lo, hi = get(f"SERVO{n}_MIN"), get(f"SERVO{n}_MAX")
    start = get(f"SERVO{n}_TRIM") if centred else lo
    throttle = max(0.0, min(1.0, ctx.state.throttle_pct / 100.0)) if ctx.state.armed else 0.0
    if get(f"SERVO{n}_REVERSED"):
        return int(start - (start - lo) * throttle) if centred else int(hi - (hi - lo) * throttle)
    return int(start + (hi - start) * throttle)


def plane_throttle_pwm(ctx, n: int) -> int | None:
    return _throttle_pwm(ctx, n, centred=False)


def rover_throttle_pwm(ctx, n: int) -> int | None:
    return _throttle_pwm(ctx, n, centred=True)
