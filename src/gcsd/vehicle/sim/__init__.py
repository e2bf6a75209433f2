"""The simulation: vehicle state, setpoints, per-type dynamics, the simulated environment.

Pure code: everything advances by a `dt` in simulated seconds handed in by the caller (the
autopilot, which multiplies real time by `speedup`). `SimulatedVehicle` is the default vehicle
backend; `gcsd.embed` lets a program supply its own.
"""

from gcsd.vehicle.sim.environment import Environment
from gcsd.vehicle.sim.fixedwing import FixedWingDynamics
from gcsd.vehicle.sim.ground import GroundDynamics
from gcsd.vehicle.sim.limits import Limits
from gcsd.vehicle.sim.multirotor import BlimpDynamics, MultirotorDynamics
from gcsd.vehicle.sim.simulation import MAX_STEP_S, Dynamics, SimulatedVehicle
from gcsd.vehicle.sim.state import Kind, Landed, Setpoint, VehicleState
from gcsd.vehicle.sim.tracker import StaticDynamics, TrackerDynamics
from gcsd.vehicle.sim.underwater import SubmarineDynamics

__all__ = [
    "MAX_STEP_S", "BlimpDynamics", "Dynamics", "Environment", "FixedWingDynamics", "GroundDynamics", "Kind",
    "Landed", "Limits", "MultirotorDynamics", "Setpoint", "SimulatedVehicle", "StaticDynamics",
    "SubmarineDynamics", "TrackerDynamics", "VehicleState",
]
