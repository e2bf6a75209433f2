"""Vehicle types: data and small hooks. Nothing outside this package asks which vehicle it is."""

from .base import VehicleType
from .copter import COPTER

VEHICLE_TYPES: dict[str, VehicleType] = {COPTER.name: COPTER}


def vehicle_type(name: str) -> VehicleType:
    try:
        return VEHICLE_TYPES[name]
    except KeyError:
        raise ValueError(f"vehicle type {name!r} is not available yet (have: {', '.join(VEHICLE_TYPES)})") from None
