"""What a vehicle type supplies: data plus a few functions of the vehicle state.

A VehicleType is MAV_TYPE, ArduPilot's mode numbers and names (from pymavlink's mode maps),
what each mode does (a `Behaviour`), the dynamics the simulation uses, which of ArduPilot's
parameters of its type (params/data/) its `settings(get)` turns into SI `Settings`, its
banner, its pre-arm checks, its command differences (extra COMMAND_LONG/INT handlers), the messages it does not produce, and
ArduPilot's default stream rates for it. The services and the autopilot ask it, never
`if copter:`.

Stream rates: `ardupilot_stream_rates` records ArduPilot's per-vehicle SRn_/MAVn_ defaults
(REFERENCE.md section 1) for reference and for configurations that want them; gcsd's own
default is SPEC.md's YAML contract (the same streams for every vehicle type, so a ground
station that never sends REQUEST_DATA_STREAM still sees telemetry). Decision recorded in
docs/vehicles.md.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from gcsd import __version__
from gcsd.vehicle.autopilot.settings import Behaviour, Settings
from gcsd.vehicle.sim import VehicleState
from gcsd.vehicle.types.firmware import version_string
from gcsd.wire.streams import STREAM_NAMES

M = mavlink
COMPANION_BANNER = f"gcsd {__version__} (companion computer)"


def stream_rates(*rates: int) -> dict[str, int]:
    """ArduPilot's order: RAW_SENS, EXT_STAT, RC_CHAN, RAW_CTRL, POSITION, EXTRA1..3, PARAMS, ADSB."""
    return dict(zip(STREAM_NAMES, rates, strict=True))


def modes_named(modes: dict[int, str], **behaviours: Behaviour) -> dict[int, Behaviour]:
    """Mode number -> behaviour, from mode names; every mode gets one (HOLD unless named)."""
    by_name = {name: number for number, name in modes.items()}
    unknown = set(behaviours) - set(by_name)
    if unknown:
        raise ValueError(f"modes not in the mode map: {sorted(unknown)}")
    return {number: behaviours.get(name, Behaviour.HOLD) for number, name in modes.items()}


@dataclass(frozen=True)
class VehicleType:
    name: str
    mav_type: int
    modes: dict[int, str]  # ArduPilot mode number -> name
    initial_mode: int
    capabilities: int  # MAV_PROTOCOL_CAPABILITY bits this vehicle type implements
    guided_modes: frozenset[int] = frozenset()
    manual_modes: frozenset[int] = frozenset()
    armable_modes: frozenset[int] | None = None  # None: any mode
    # extra COMMAND_LONG/INT handlers: command id -> handler(node, request) -> MAV_RESULT
    commands: dict[int, Callable] = field(default_factory=dict)
    behaviours: dict[int, Behaviour] = field(default_factory=dict)
    dynamics: Callable[[], object] | None = None  # None: nothing moves (a companion computer)
    # the parameters settings() reads (the autopilot reloads them on a change); the whole set is
    # ArduPilot's, as data: params/data/<param_set or name>.tsv (gcsd.vehicle.params.defs)
    params: tuple[str, ...] = ()
    param_set: str = ""
    firmware: str = ""  # the banner's firmware name (ArduCopter...); "" for a companion computer
    banner_lines: Callable[[Callable[[str], float]], list[str]] = lambda get: []
    motor_pwm: Callable | None = None  # (node, n) -> PWM of output n if it drives a motor or throttle
    settings: Callable[[Callable[[str], float]], Settings] = lambda get: Settings()
    prearm_checks: tuple[Callable, ...] = ()
    not_produced: frozenset[int] = frozenset()  # message ids this vehicle never sends
    # message ids kept out of its streams but sent when a client asks for them
    # (SET_MESSAGE_INTERVAL, REQUEST_MESSAGE): a companion's SYS_STATUS, SYSTEM_TIME...
    not_streamed: frozenset[int] = frozenset()
    # HEARTBEAT.autopilot: MAV_AUTOPILOT_INVALID for a component that is no autopilot (a
    # companion computer), which clients then never take for the vehicle
    autopilot: int = M.MAV_AUTOPILOT_ARDUPILOTMEGA
    # False: no mission, fence, rally or home of its own (a companion computer: they are the
    # flight controller's, and a default home would be a made-up one)
    has_mission: bool = True
    ardupilot_stream_rates: dict[str, int] = field(default_factory=dict)
    can_arm: bool = True  # a companion computer has nothing to arm
    # PREFLIGHT_CALIBRATION param4 1 (ArduPlane's / Rover's trim_radio): the sticks (by rc.STICKS
    # index) whose RCn_TRIM takes the current input; () = UNSUPPORTED (ArduCopter)
    radio_trim_sticks: tuple[int, ...] = ()

    def parameter_set(self) -> str:
        return self.param_set or self.name

    def banner(self, get: Callable[[str], float]) -> list[str]:
        """The banner STATUSTEXTs, as ArduPilot sends them (gcsd.vehicle.types.firmware)."""
        if not self.firmware:
            return [COMPANION_BANNER]
        return [version_string(self.firmware)] + self.banner_lines(get)

    def base_mode(self, state: VehicleState) -> int:
        if self.autopilot == M.MAV_AUTOPILOT_INVALID:
            return 0  # no modes, nothing armed: MAVLink's (and ArduPilot's) convention for a companion
        base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if state.armed:
            base |= M.MAV_MODE_FLAG_SAFETY_ARMED
        if state.mode in self.guided_modes:
            base |= M.MAV_MODE_FLAG_GUIDED_ENABLED
        if state.mode not in self.manual_modes:
            base |= M.MAV_MODE_FLAG_STABILIZE_ENABLED
        base |= M.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
        return base

    def system_status(self, state: VehicleState) -> int:
        if state.failsafe is not None and state.armed:
            return M.MAV_STATE_CRITICAL
        return M.MAV_STATE_ACTIVE if state.armed else M.MAV_STATE_STANDBY

    def mode_number(self, name: str) -> int | None:
        for number, mode_name in self.modes.items():
            if mode_name == name.upper():
                return number
        return None

    def mode_name(self, number: int) -> str:
        return self.modes.get(number, f"Mode({number})")

    def can_arm_in(self, mode: int) -> bool:
        return self.armable_modes is None or mode in self.armable_modes

    def behaviour(self, mode: int) -> Behaviour:
        return self.behaviours.get(mode, Behaviour.HOLD)

    def produces(self, msgid: int) -> bool:
        return msgid not in self.not_produced

    def streams(self, msgid: int) -> bool:
        """Whether `msgid` is in this vehicle's streams (SRn_, REQUEST_DATA_STREAM)."""
        return msgid not in self.not_produced and msgid not in self.not_streamed
