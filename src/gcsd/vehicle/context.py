"""What a service sees of the vehicle it serves: the `ServiceContext` protocol, and its ports.

Services (services/), the vehicle types' command handlers (vehicles/) and the autopilot take a
`ServiceContext`, never the node that implements it (node.py) and never each other: the
composition root (compose.py) hands each service the other parts it needs by name (the mission
service to FTP and to the flight service, the rates service to the modes service...).
tests/unit/test_architecture.py checks that nothing under services/, vehicles/ or autopilot/
reaches past these members.

The ports:
- `control` (Control): arming and mode changes with every check a ground station's request
  goes through (pre-arm checks, the vehicle's own mode conditions), answering with the
  STATUSTEXT ArduPilot sends; the ControlService implements it.
- `autopilot` (autopilot.core.Autopilot): what the vehicle does (takeoff, guided targets,
  speed, ROI, disarm on an event...), over the simulation or an embedding backend.
- `plans` (PlanPort): the mission, fence and rally stores and their events; MissionService.

Effects: `reply(channel, msg)` answers on one channel now; `text(severity, text, channels)`
queues a STATUSTEXT for every served, non-private channel (or the ones given); `push(msgid)`
asks every link's scheduler for one message at its next pass; `wake(channel)` asks for a send
pass soon (a service with a `pending` queue); `set_slow(channel, reason, active)` slows the
link's streams (an upload in progress). Time: `now()` / `wall()` read the daemon's clock (for
code not handed `now`), `time_boot_ms(now)` / `time_usec(now)` are the vehicle's boot time.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

if TYPE_CHECKING:
    from gcsd.boundary import ErrorCounts
    from gcsd.links.channel import Channel
    from gcsd.links.link import Link
    from gcsd.vehicle.autopilot.core import Autopilot
    from gcsd.vehicle.mission.stores import FenceStore, MissionStore, RallyStore
    from gcsd.vehicle.params import ParamStore
    from gcsd.vehicle.sim.state import VehicleState
    from gcsd.vehicle.types import VehicleType


class Control(Protocol):
    """Arming and mode changes, checked as a ground station's request is (ControlService)."""

    gcs_last_seen_s: float | None  # the last HEARTBEAT from the ground station (failsafe)

    def arm(self, forced: bool = False) -> int:
        """MAV_RESULT: ACCEPTED, or FAILED with the pre-arm failures sent as STATUSTEXT."""
        ...

    def set_mode(self, number: int) -> bool:
        """False, with a STATUSTEXT, when refused."""
        ...

    def arm_by_rudder(self) -> bool: ...

    def disarm_by_rudder(self) -> bool: ...


class PlanPort(Protocol):
    """The vehicle's stored plans (MissionService) as the autopilot and the vehicle types use them."""

    mission: MissionStore
    fence: FenceStore
    rally: RallyStore
    complete: bool  # the mission ran to its end

    def home_changed(self) -> None: ...

    def item_reached(self, seq: int) -> None: ...

    def current_message(self): ...


class ServiceContext(Protocol):
    """One local vehicle, as its services see it."""

    index: int  # the vehicle's place in a swarm (0 for a single vehicle)
    sysid: int
    compid: int
    gcs_sysid: int  # SYSID_MYGCS
    min_interval_ms: int  # the fastest stream interval the scheduler keeps (SCHED_LOOP_RATE)
    params: ParamStore
    state: VehicleState
    vehicle: VehicleType  # the vehicle type's data: modes, commands, limits
    channels: list[Channel]
    errors: ErrorCounts
    control: Control
    autopilot: Autopilot
    plans: PlanPort

    def now(self) -> float: ...

    def wall(self) -> float: ...

    def time_boot_ms(self, now: float) -> int: ...

    def time_usec(self, now: float) -> int: ...

    def link(self, channel: Channel) -> Link: ...

    def reply(self, channel: Channel, msg) -> bool: ...

    def text(self, severity: int, text: str, channels: set[int] | None = None) -> None: ...

    def text_channels(self) -> set[int]: ...

    def push(self, msgid: int) -> None: ...

    def set_slow(self, channel: Channel, reason: str, active: bool) -> None: ...

    def wake(self, channel: Channel) -> None: ...

    def banner(self) -> None: ...

    def prearm_failures(self) -> list[str]: ...

    def save_params(self) -> None:
        """Parameters changed outside PARAM_SET (a reset, a calibration): written behind."""
        ...


CONTEXT_MEMBERS = frozenset(
    name for cls in (ServiceContext,) for name in (*cls.__annotations__, *vars(cls)) if not name.startswith("_")
)
