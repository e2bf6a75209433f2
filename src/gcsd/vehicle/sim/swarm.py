"""Where each vehicle of a swarm starts: vehicle N on a grid around the configured home (10 per
row, SWARM_SPACING_M apart, vehicle 1 at home), each with its own home, so a swarm does not
start inside itself."""

from __future__ import annotations

from gcsd.vehicle.sim.geo import offset
from gcsd.vehicle.sim.state import VehicleState

SWARM_SPACING_M = 5.0
SWARM_ROW = 10


def initial_state(vehicle, home, index: int, capacity_mah: float) -> VehicleState:
    north = (index // SWARM_ROW) * SWARM_SPACING_M
    east = (index % SWARM_ROW) * SWARM_SPACING_M
    lat, lon = offset(home.lat, home.lon, north, east) if index else (home.lat, home.lon)
    return VehicleState(
        lat=lat, lon=lon, alt_amsl_m=home.alt, home_lat=lat, home_lon=lon, home_alt_m=home.alt,
        mode=vehicle.initial_mode, capacity_mah=capacity_mah,
    )
