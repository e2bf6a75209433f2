"""Vehicle types: data and small hooks. Nothing outside this package asks which vehicle it is."""

from gcsd.vehicle.params.defs import vehicle_defs
from gcsd.vehicle.types.base import VehicleType
from gcsd.vehicle.types.blimp import BLIMP
from gcsd.vehicle.types.companion import COMPANION
from gcsd.vehicle.types.copter import COPTER
from gcsd.vehicle.types.plane import PLANE
from gcsd.vehicle.types.prearm import prearm_failures
from gcsd.vehicle.types.rover import ROVER
from gcsd.vehicle.types.sub import SUB
from gcsd.vehicle.types.tracker import TRACKER

VEHICLE_TYPES: dict[str, VehicleType] = {v.name: v for v in (COPTER, PLANE, ROVER, SUB, TRACKER, BLIMP, COMPANION)}


def vehicle_type(name: str) -> VehicleType:
    try:
        return VEHICLE_TYPES[name]
    except KeyError:
        raise ValueError(f"vehicle type {name!r} is not available (have: {', '.join(VEHICLE_TYPES)})") from None


def vehicle_params(vehicle: VehicleType, sysid: int, gcs_sysid: int, enforce: bool,
                   channel_rates: list[dict[str, float]], speedup: float) -> list:
    """ArduPilot's parameter set of the vehicle type, with the configured defaults (gcsd.vehicle.params.defs)."""
    return vehicle_defs(vehicle.parameter_set(), sysid, gcs_sysid, enforce, channel_rates, speedup)


__all__ = ["VEHICLE_TYPES", "VehicleType", "prearm_failures", "vehicle_params", "vehicle_type"]
