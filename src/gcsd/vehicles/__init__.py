"""Vehicle types: data and small hooks. Nothing outside this package asks which vehicle it is."""

from .base import VehicleType
from .blimp import BLIMP
from .common import sim_params
from .companion import COMPANION
from .copter import COPTER
from .plane import PLANE
from .prearm import prearm_failures
from .rover import ROVER
from .sub import SUB
from .tracker import TRACKER

VEHICLE_TYPES: dict[str, VehicleType] = {v.name: v for v in (COPTER, PLANE, ROVER, SUB, TRACKER, BLIMP, COMPANION)}


def vehicle_type(name: str) -> VehicleType:
    try:
        return VEHICLE_TYPES[name]
    except KeyError:
        raise ValueError(f"vehicle type {name!r} is not available (have: {', '.join(VEHICLE_TYPES)})") from None


def vehicle_params(vehicle: VehicleType, speedup: float) -> tuple:
    """The vehicle type's own parameters, plus the simulation's when something moves."""
    return vehicle.params + (sim_params(speedup) if vehicle.dynamics is not None else ())


__all__ = ["VEHICLE_TYPES", "VehicleType", "prearm_failures", "vehicle_params", "vehicle_type"]
