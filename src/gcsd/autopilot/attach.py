"""How a vehicle node gets its vehicle: the initial state and the vehicle's services.

`initial_state` puts vehicle N of a swarm on a grid around the configured home (10 per row,
SWARM_SPACING_M apart, vehicle 1 at home), each with its own home, so a swarm does not start
inside itself. `attach_services` adds the flying commands and guided messages, the
maintenance commands, the payload commands (`services.peripherals`), HIGH_LATENCY2 control and (when configured) SERIAL_CONTROL passthrough.
"""

from __future__ import annotations

from pathlib import Path

from ..sim.geo import offset
from ..sim.state import VehicleState

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


def attach_services(node, config) -> None:
    from ..services.flight import FlightService
    from ..services.highlatency import HighLatencyService
    from ..services.maintenance import MaintenanceService
    from ..services.modes import ModesService
    from ..services.peripherals import PeripheralService

    ftp_root = Path(node.state_dir) / config.ftp.root if node.state_dir is not None else None
    node.add_service(FlightService(node))
    node.add_service(MaintenanceService(node, ftp_root))
    node.add_service(PeripheralService(node))
    node.add_service(ModesService(node))  # AVAILABLE_MODES; other REQUEST_MESSAGEs go on to the rates service
    node.add_service(HighLatencyService(node))
    serial_control = getattr(config, "serial_control", ())
    if serial_control and node.index == 0:  # one owner per device, even in a swarm
        from ..services.serialcontrol import SerialControlService
        node.add_service(SerialControlService(node, serial_control))
    # The vehicle type's own command handlers win over the generic services' (CONDITION_YAW is a
    # copter's in any mode and UNSUPPORTED on a plane, a rover has no landing gear...).
    node.commands.table.update({cmd: (lambda req, h=h: h(node, req)) for cmd, h in node.vehicle.commands.items()})
