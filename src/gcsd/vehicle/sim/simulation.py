"""The default vehicle backend: the simulation. It moves the state toward the setpoint.

`SimulatedVehicle.update(state, setpoint, limits, dt_s)` applies, in simulated seconds: the
wind and the GPS of the environment, the vehicle type's dynamics (multirotor, fixed wing,
ground, submarine, tracker, static) and the battery drain. It is pure: no clock, no I/O; the
autopilot calls it with `dt_s` already multiplied by the speedup and cut into steps of at most
MAX_STEP_S, so kinematics stay stable at any speedup.
"""

from __future__ import annotations

from typing import Protocol

from gcsd.vehicle.sim.environment import Environment, apply_battery, apply_gps, apply_wind
from gcsd.vehicle.sim.limits import Limits
from gcsd.vehicle.sim.state import Setpoint, VehicleState

MAX_STEP_S = 0.1


class Dynamics(Protocol):
    def step(self, s: VehicleState, sp: Setpoint, lim: Limits, dt: float) -> None: ...


CALM = Environment()  # no wind, good GPS (frozen: one shared default)


class SimulatedVehicle:
    def __init__(self, dynamics: Dynamics, environment: Environment = CALM) -> None:
        self.dynamics = dynamics
        self.environment = environment

    def update(self, state: VehicleState, setpoint: Setpoint, limits: Limits, dt_s: float) -> None:
        env = self.environment
        apply_wind(state, env)
        apply_gps(state, env)
        self.dynamics.step(state, setpoint, limits, dt_s)
        apply_battery(state, limits, dt_s)
