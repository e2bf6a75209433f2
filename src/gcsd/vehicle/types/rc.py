"""RC input as ArduPilot reads it: channel mapping, calibration, the flight-mode switch, RC loss.

gcsd has no radio receiver of its own; its RC input is a receiver whose sticks rest at each
RCn_TRIM, overridden per channel by RC_CHANNELS_OVERRIDE / MANUAL_CONTROL (held
RC_OVERRIDE_TIME seconds). Decisions, and why:

- Sticks: roll, pitch, throttle and yaw are read from the channels RCMAP_ROLL, RCMAP_PITCH,
  RCMAP_THROTTLE and RCMAP_YAW name (1..4 by default), each scaled as RC_Channel's
  pwm_to_angle_dz does: 0 within RCn_TRIM +- RCn_DZ, then linear to -1 at RCn_MIN and +1 at
  RCn_MAX, negated when RCn_REVERSED. (The multirotor simulation reads the throttle stick as
  a climb rate around mid-stick, as ALT_HOLD does.)
- Flight-mode switch: the channel FLTMODE_CH (copter, plane) or MODE_CH (rover) selects
  FLTMODE1..6 / MODE1..6 with ArduPilot's PWM bands (< 1231, < 1361, < 1491, < 1621, < 1750,
  above); a value at or below 900 or at or above 2200 is ignored, as RC_Channel's
  read_mode_switch does. A new position must hold 200 ms (SWITCH_DEBOUNCE_TIME_MS) before
  the mode changes; the switch's position at start (the channel at rest) changes nothing, as
  RC_Channels::reset_mode_switch. A refused mode change says why (STATUSTEXT), as a ground
  station's would. Channel 0 (FLTMODE_CH 0) disables the switch.
- RC loss: once a ground station has driven the RC input with overrides, their lapse is the
  loss of RC (ArduPilot without a receiver: has_valid_input() is false when overrides time
  out), and so is a throttle channel below the failsafe value (FS_THR_VALUE, plane
  THR_FS_VALUE: a receiver that signals loss by low throttle). Until overrides are first used
  the receiver at rest is valid, so a vehicle flown only by mission commands never has an RC
  failsafe. While RC is lost the mode switch is not read.
- Rudder arming (ARMING_RUDDER 1 arm, 2 arm and disarm): throttle at zero (at or below
  RCn_MIN + RCn_DZ of the throttle channel) and yaw full right (beyond 4000 of 4500) held 2 s
  arms, through the same pre-arm checks as a command; full left held 2 s disarms on the ground
  (ArduCopter's arm_motors_check, ARM_DELAY / DISARM_DELAY of 2 s).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

SWITCH_DEBOUNCE_S = 0.2
RUDDER_HOLD_S = 2.0
RUDDER_FULL = 4000 / 4500  # yaw beyond this fraction of full deflection
PWM_VALID = (900, 2200)  # exclusive: RC_MIN_LIMIT_PWM / RC_MAX_LIMIT_PWM in read_mode_switch
BANDS = (1231, 1361, 1491, 1621, 1750)
STICKS = ("RCMAP_ROLL", "RCMAP_PITCH", "RCMAP_THROTTLE", "RCMAP_YAW")
DEFAULT_MAP = (1, 2, 3, 4)

Get = Callable[[str], float]


def switch_position(pwm: int) -> int | None:
    """0..5 for FLTMODE1..6; None for a value read_mode_switch ignores."""
    if not PWM_VALID[0] < pwm < PWM_VALID[1]:
        return None
    return next((i for i, edge in enumerate(BANDS) if pwm < edge), len(BANDS))


def mapped_channel(params, index: int) -> int:
    """The RC channel of stick `index` (0 roll, 1 pitch, 2 throttle, 3 yaw): RCMAP_*, or 1..4."""
    name = STICKS[index]
    channel = int(params.clamped(name)) if name in params else DEFAULT_MAP[index]
    return channel if 1 <= channel <= 16 else DEFAULT_MAP[index]  # RCMAP_* 0 or wild: the default


def scaled(get: Get, n: int, pwm: int) -> float:
    """pwm_to_angle_dz: -1..1 around RCn_TRIM with the dead zone RCn_DZ, RCn_REVERSED."""
    trim, dz = get(f"RC{n}_TRIM"), get(f"RC{n}_DZ")
    high, low = trim + dz, trim - dz
    if pwm > high and get(f"RC{n}_MAX") > high:
        value = (pwm - high) / (get(f"RC{n}_MAX") - high)
    elif pwm < low and low > get(f"RC{n}_MIN"):
        value = (pwm - low) / (low - get(f"RC{n}_MIN"))
    else:
        value = 0.0
    value = max(-1.0, min(1.0, value))
    return -value if get(f"RC{n}_REVERSED") else value


def mode_switch_names(params) -> tuple[str, str] | None:
    """(channel parameter, mode parameter prefix) of the vehicle type's mode switch."""
    for channel, prefix in (("FLTMODE_CH", "FLTMODE"), ("MODE_CH", "MODE")):
        if channel in params and f"{prefix}1" in params:
            return channel, prefix
    return None


def failsafe_names(params) -> tuple[str, str] | None:
    """(enable parameter, PWM threshold parameter) of the vehicle type's throttle failsafe."""
    for enable, value in (("FS_THR_ENABLE", "FS_THR_VALUE"), ("THR_FAILSAFE", "THR_FS_VALUE")):
        if enable in params and value in params:
            return enable, value
    return None


@dataclass
class RcInput:
    """The RC input's state between autopilot ticks: overrides used, the mode switch."""

    used: bool = False  # a ground station has driven the RC input with overrides
    position: int | None = None  # the mode switch's settled position
    pending: tuple[int, float] | None = None  # a new position and when it was first seen
    rudder: tuple[str, float] | None = None  # "arm" / "disarm" held since

    def value(self, params, override: dict[int, int], n: int) -> int:
        return override.get(n) or int(params.clamped(f"RC{n}_TRIM"))

    def lost(self, params, override: dict[int, int]) -> bool:
        """RC is lost: overrides lapsed after being used, or throttle below the failsafe value."""
        if self.used and not override:
            return True
        names = failsafe_names(params)
        if names is None or not params.clamped(names[0]):
            return False
        throttle = self.value(params, override, mapped_channel(params, 2))
        return throttle < params.clamped(names[1])

    def sticks(self, params, override: dict[int, int]) -> tuple[float, float, float, float]:
        if not override:
            return (0.0, 0.0, 0.0, 0.0)
        get = params.clamped
        out = []
        for index in range(4):
            n = mapped_channel(params, index)
            out.append(scaled(get, n, override[n]) if n in override else 0.0)
        return out[0], out[1], out[2], out[3]

    def mode_switch(self, params, override: dict[int, int], now: float) -> int | None:
        """The mode number FLTMODEn / MODEn asks for now that the switch settled in a new
        position, else None."""
        names = mode_switch_names(params)
        if names is None or self.lost(params, override):
            return None
        channel = int(params.clamped(names[0]))
        if not 1 <= channel <= 16:
            return None
        if self.position is None:  # the switch at rest at start: reset_mode_switch, no change
            self.position = switch_position(int(params.clamped(f"RC{channel}_TRIM")))
        position = switch_position(self.value(params, override, channel))
        if position is None:
            return None
        if position == self.position:
            self.pending = None
            return None
        if self.pending is None or self.pending[0] != position:
            self.pending = (position, now)
            return None
        if now - self.pending[1] < SWITCH_DEBOUNCE_S:
            return None
        self.position, self.pending = position, None
        return int(params.clamped(f"{names[1]}{position + 1}"))

    def rudder_arming(self, params, override: dict[int, int], now: float, armed: bool) -> str | None:
        """"arm" or "disarm" once the rudder gesture has been held RUDDER_HOLD_S, else None."""
        mode = int(params.clamped("ARMING_RUDDER")) if "ARMING_RUDDER" in params else 0
        throttle, yaw = mapped_channel(params, 2), mapped_channel(params, 3)
        gesture = None
        if mode and throttle in override and yaw in override and not self.lost(params, override):
            low = override[throttle] <= params.clamped(f"RC{throttle}_MIN") + params.clamped(f"RC{throttle}_DZ")
            stick = scaled(params.clamped, yaw, override[yaw])
            if low and stick > RUDDER_FULL and not armed:
                gesture = "arm"
            elif low and stick < -RUDDER_FULL and armed and mode == 2:
                gesture = "disarm"
        if gesture is None:
            self.rudder = None
            return None
        if self.rudder is None or self.rudder[0] != gesture:
            self.rudder = (gesture, now)
            return None
        if now - self.rudder[1] < RUDDER_HOLD_S:
            return None
        self.rudder = ("done", now)  # once per gesture: released and held again to repeat
        return gesture
