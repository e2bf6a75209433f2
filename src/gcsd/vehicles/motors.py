"""A multicopter's motor outputs as ArduPilot's AP_MotorsMulticopter writes them.

FRAME_CLASS decides how many motors the frame has (gcsd.vehicles.firmware.FRAME_CLASSES: QUAD 4,
HEXA 6, OCTA 8, Y6 6, TRI 3, ...). Output n drives motor m when SERVOn_FUNCTION is Motor m (33..40,
82..85 for 9..12), or when it is 0 and n is one of the frame's motors (ArduPilot assigns the
default channels of a new frame at its next start). A motor function the frame does not use
outputs 0. The PWM range is MOT_PWM_MIN..MOT_PWM_MAX (0: RC3_MIN..RC3_MAX, as
get_pwm_output_min/max): disarmed the minimum; armed on the ground MOT_SPIN_ARM of the range
(ground idle); in the air MOT_SPIN_MIN..MOT_SPIN_MAX scaled by the simulated throttle.
"""

from __future__ import annotations

from .firmware import motor_count

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


def copter_motor_pwm(node, n: int) -> int | None:
    """SERVO_OUTPUT_RAW for output n if it is a motor output (None: not a motor)."""
    get = node.params.get
    motor = motor_of_output(get, n)
    if motor is None:
        return None
    if motor > motor_count(get):
        return 0
    lo, hi = pwm_range(get)
    s = node.state
    if not s.armed:
        return int(lo)
    throttle = max(0.0, min(1.0, s.throttle_pct / 100.0))
    if s.on_ground:  # spooled to ground idle (the simulation has no spool-up on the ground)
        thrust = get("MOT_SPIN_ARM")
    else:
        thrust = get("MOT_SPIN_MIN") + (get("MOT_SPIN_MAX") - get("MOT_SPIN_MIN")) * throttle
    return int(lo + (hi - lo) * thrust)
