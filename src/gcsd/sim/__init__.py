"""The simulation: vehicle state, setpoints, per-type dynamics, the simulated environment.

Pure code: everything advances by a `dt` in simulated seconds handed in by the caller (the
autopilot, which multiplies real time by `speedup`). `SimulatedVehicle` is the default vehicle
backend; `gcsd.embed` lets a program supply its own.
"""

from .environment import Environment
from .fixedwing import FixedWingDynamics
from .ground import GroundDynamics
from .limits import Limits
from .multirotor import BlimpDynamics, MultirotorDynamics
from .simulation import MAX_STEP_S, Dynamics, SimulatedVehicle
from .state import Kind, Landed, Setpoint, VehicleState
from .tracker import StaticDynamics, TrackerDynamics
from .underwater import SubmarineDynamics

__all__ = [
    "MAX_STEP_S", "BlimpDynamics", "Dynamics", "Environment", "FixedWingDynamics", "GroundDynamics", "Kind",
    "Landed", "Limits", "MultirotorDynamics", "Setpoint", "SimulatedVehicle", "StaticDynamics",
    "SubmarineDynamics", "TrackerDynamics", "VehicleState",
]
