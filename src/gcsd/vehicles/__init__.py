"""Vehicle types: data and small hooks. Nothing outside this package asks which vehicle it is."""

from ..params.defs import vehicle_defs
from .base import VehicleType
from .blimp import BLIMP
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


def vehicle_params(vehicle: VehicleType, sysid: int, gcs_sysid: int, enforce: bool,
                   channel_rates: list[dict[str, float]], speedup: float) -> list:
    """ArduPilot's parameter set of the vehicle type, with the configured defaults (gcsd.params.defs)."""
    return vehicle_defs(vehicle.parameter_set(), sysid, gcs_sysid, enforce, channel_rates, speedup)


__all__ = ["VEHICLE_TYPES", "VehicleType", "prearm_failures", "vehicle_params", "vehicle_type"]
