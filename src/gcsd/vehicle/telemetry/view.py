"""TelemetryView: the vehicle as the telemetry producers read it, and nothing more.

Producers (producers.py, vehicle.py) are pure functions `producer(view, channel, now)`; they
read these members and return a message or None. The node implements the view; a unit test
can hand producers any object with these members.
"""

from __future__ import annotations

from typing import Any, Protocol


class TelemetryView(Protocol):
    state: Any  # sim.state.VehicleState: position, attitude, battery, mode, arming...
    vehicle: Any  # vehicles.VehicleType: MAV_TYPE, modes, motor layout
    params: Any  # params.ParamStore
    autopilot: Any  # autopilot.core.Autopilot: failsafes, the target speed
    plans: Any  # context.PlanPort: the current mission item

    def time_boot_ms(self, now: float) -> int: ...

    def time_usec(self, now: float) -> int: ...

    def wall(self) -> float: ...

    def capabilities(self) -> int: ...

    def comm_error_count(self) -> int: ...

    def prearm_failures(self) -> list[str]: ...


VIEW_MEMBERS = frozenset(name for name in (*TelemetryView.__annotations__, *vars(TelemetryView))
                         if not name.startswith("_"))
