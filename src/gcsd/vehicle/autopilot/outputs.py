"""Servo and relay outputs set by commands and mission items, with their repeats.

DO_SET_SERVO sets servo n (1..16) to a PWM until changed; it is refused for an output that
drives a motor (SERVOn_FUNCTION 33..40), as ArduPilot refuses a channel already in use.
DO_REPEAT_SERVO alternates between that PWM and SERVOn_TRIM `count` times, each half-cycle
`cycle_s`/2 long; DO_SET_RELAY switches relay n (0-based, 0..5); DO_REPEAT_RELAY toggles it
`count` times every `cycle_s`/2. Time is simulated seconds (`tick(dt)`); the values live in the
vehicle state (`servo_override`, `relays`), which SERVO_OUTPUT_RAW reports.
"""

from __future__ import annotations

from dataclasses import dataclass

from gcsd.vehicle.sim.state import RELAY_COUNT, SERVO_COUNT

MOTOR_FUNCTIONS = range(33, 41)


@dataclass
class _Repeat:
    kind: str  # "servo" | "relay"
    index: int
    pwm: int
    toggles_left: int
    half_cycle_s: float
    until_s: float
    on: bool = True


class Outputs:
    def __init__(self, state, params) -> None:
        self.state = state
        self.params = params
        self._repeat: _Repeat | None = None
        self._t = 0.0

    def servo_usable(self, n: int) -> bool:
        if not 1 <= n <= SERVO_COUNT:
            return False
        return self.params.get(f"SERVO{n}_FUNCTION") not in MOTOR_FUNCTIONS

    def set_servo(self, n: int, pwm: int) -> bool:
        if not self.servo_usable(n) or not 0 <= pwm <= 65535:
            return False
        if self._repeat is not None and self._repeat.kind == "servo" and self._repeat.index == n:
            self._repeat = None
        self.state.servo_override[n] = int(pwm)
        return True

    def set_relay(self, n: int, on: bool) -> bool:
        if not 0 <= n < RELAY_COUNT:
            return False
        if self._repeat is not None and self._repeat.kind == "relay" and self._repeat.index == n:
            self._repeat = None
        self.state.relays[n] = bool(on)
        return True

    def repeat_servo(self, n: int, pwm: int, count: int, cycle_s: float) -> bool:
        if count < 1 or cycle_s <= 0 or not self.set_servo(n, pwm):
            return False
        self._repeat = _Repeat("servo", n, int(pwm), 2 * int(count) - 1, cycle_s / 2.0, self._t + cycle_s / 2.0)
        return True

    def repeat_relay(self, n: int, count: int, cycle_s: float) -> bool:
        if count < 0 or not 0 <= n < RELAY_COUNT:
            return False
        if count == 0:
            return True  # ArduPilot's do_repeat_relay takes a zero count: nothing toggles (SITL ACCEPTS it)
        if cycle_s <= 0:
            return False
        self.set_relay(n, not self.state.relays[n])
        self._repeat = _Repeat("relay", n, 0, 2 * int(count) - 1, cycle_s / 2.0, self._t + cycle_s / 2.0)
        return True

    def tick(self, dt: float) -> None:
        self._t += dt
        self._end_motor_test()
        r = self._repeat
        while r is not None and self._t >= r.until_s:
            if r.toggles_left <= 0:
                self._repeat = None
                return
            r.toggles_left -= 1
            r.on = not r.on
            r.until_s += r.half_cycle_s
            if r.kind == "servo":
                trim = int(self.params.clamped(f"SERVO{r.index}_TRIM"))
                self.state.servo_override[r.index] = r.pwm if r.on else trim
            else:
                self.state.relays[r.index] = not self.state.relays[r.index]

    def motor_test(self, n: int, pwm: int, seconds: float) -> None:
        """DO_MOTOR_TEST: drive motor output n at pwm for `seconds` (simulated), then release it."""
        self.state.servo_override[n] = int(pwm)
        self._motor_test = (n, self._t + seconds)

    def _end_motor_test(self) -> None:
        test = getattr(self, "_motor_test", None)
        if test is not None and self._t >= test[1]:
            self.state.servo_override.pop(test[0], None)
            self._motor_test = None
