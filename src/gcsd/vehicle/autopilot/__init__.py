"""The autopilot: modes as behaviours, guided targets, missions, RTL, landing and failsafes,
driving a vehicle backend (the simulation by default; see gcsd.embed)."""

from gcsd.vehicle.autopilot.settings import DISARM, Behaviour, Settings

__all__ = ["DISARM", "Behaviour", "Settings"]
