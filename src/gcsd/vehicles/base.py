"""What a vehicle type supplies: MAV_TYPE, ArduPilot's mode numbers, capabilities, hooks.

A VehicleType is data plus a few functions of the vehicle state. The services ask it, never
`if copter:`. Mode tables come from pymavlink's mode maps (the numbers ArduPilot uses).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from ..sim import VehicleState

M = mavlink


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

    def base_mode(self, state: VehicleState) -> int:
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
        return M.MAV_STATE_ACTIVE if state.armed else M.MAV_STATE_STANDBY

    def mode_number(self, name: str) -> int | None:
        for number, mode_name in self.modes.items():
            if mode_name == name.upper():
                return number
        return None

    def can_arm_in(self, mode: int) -> bool:
        return self.armable_modes is None or mode in self.armable_modes
