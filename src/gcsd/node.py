"""A local MAVLink component: one simulated vehicle (sysid, compid) and its services.

The node owns the vehicle state and simulation, one Link (scheduler + stream rates) per
channel, the STATUSTEXT queue, and the dispatch tables built from its services: message name ->
`handle_<NAME>` method, command id -> handler. It handles only what the router says is for it.

Messages from other systems are accepted unless `gcs.enforce_sysid` is set, in which case only
our own sysid and the GCS sysid get through (RADIO_STATUS always does), as MAV_OPTIONS bit 0.
An exception in a handler is logged with its traceback and counted; the channel and the daemon
keep running.
"""

from __future__ import annotations

from typing import Callable

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from .channel import MAX_FRAME_BYTES, Channel
from .clock import Clock
from .codec import Frame
from .link import Link
from .services import Incoming
from .services.commands import CommandService
from .services.control import ControlService
from .services.rates import RatesService
from .services.statustext import StatusTextQueue
from .services.timesync import TimesyncService
from .sim import Simulation, VehicleState
from .telemetry import PRODUCERS
from .vehicles import VehicleType

log = structlog.get_logger("gcsd.node")

ALWAYS_ACCEPTED = frozenset({"RADIO_STATUS", "RADIO"})
BANNER = ("gcsd 0.1.0 (ArduPilot-compatible MAVLink vehicle)",)


class VehicleNode:
    def __init__(
        self,
        sysid: int,
        compid: int,
        vehicle: VehicleType,
        state: VehicleState,
        clock: Clock,
        channels: list[Channel],
        wake: Callable[[Channel], None],
        gcs_sysid: int = 255,
        enforce_gcs_sysid: bool = False,
        speedup: float = 1.0,
    ) -> None:
        self.sysid = sysid
        self.compid = compid
        self.vehicle = vehicle
        self.state = state
        self.clock = clock
        self.channels = channels
        self.gcs_sysid = gcs_sysid
        self.enforce_gcs_sysid = enforce_gcs_sysid
        now = clock.now()
        self.sim = Simulation(state, now, speedup)
        self.statustext = StatusTextQueue()
        self.handler_errors = 0
        self._wake = wake
        self.links = [Link(ch, now, self._producible, lambda ch=ch: wake(ch)) for ch in channels]
        self.control = ControlService(self)
        self.rates = RatesService(self)
        self.services = [self.control, self.rates, TimesyncService(self)]
        table: dict[int, Callable] = {}
        for service in self.services:
            table.update(service.commands())
        table.update({cmd: (lambda req, h=h: h(self, req)) for cmd, h in vehicle.commands.items()})
        self.commands = CommandService(self, table)
        self.services.append(self.commands)
        self.handlers: dict[str, Callable[[Incoming], None]] = {}
        for service in self.services:
            self.handlers.update(service.message_handlers())

    # --- identity and time -----------------------------------------------------------------
    def capabilities(self) -> int:
        caps = self.vehicle.capabilities
        for service in self.services:
            caps |= service.capabilities
        return caps

    def time_boot_ms(self, now: float) -> int:
        return int(self.clock.since_boot(now) * 1000) & 0xFFFFFFFF

    def time_usec(self, now: float) -> int:
        return int(self.clock.since_boot(now) * 1e6)

    def parse_error_count(self) -> int:
        return sum(ch.stats.drops for ch in self.channels) & 0xFFFF

    def _producible(self, msgid: int) -> bool:
        return msgid in PRODUCERS

    def link(self, channel: Channel) -> Link:
        return self.links[channel.index]

    # --- receive ---------------------------------------------------------------------------
    def handle(self, channel: Channel, frame: Frame, now: float) -> None:
        name = frame.name
        handler = self.handlers.get(name)
        if handler is None:
            return
        if (
            self.enforce_gcs_sysid
            and frame.sysid not in (self.gcs_sysid, self.sysid)
            and name not in ALWAYS_ACCEPTED
        ):
            return
        try:
            handler(Incoming(frame.msg, frame, channel, now))
        except Exception:
            self.handler_errors += 1
            log.exception("handler_failed", channel=channel.name, msg=name, sysid=frame.sysid, compid=frame.compid)

    # --- send ------------------------------------------------------------------------------
    def reply(self, channel: Channel, msg) -> bool:
        """Send one message on one channel now (acks, replies)."""
        return channel.send_message(msg, self.sysid, self.compid)

    def text_channels(self) -> set[int]:
        """Where STATUSTEXT goes: active or streaming links that are not private."""
        return {
            link.channel.index
            for link in self.links
            if not link.channel.policy.private and link.channel.peers
        }

    def send_text(self, severity: int, text: str, channels: set[int] | None = None) -> None:
        self.statustext.add(severity, text, self.text_channels() if channels is None else channels, self.clock.now())
        for index in channels if channels is not None else self.text_channels():
            self._wake(self.channels[index])

    def send_banner(self) -> None:
        for line in BANNER:
            self.send_text(M.MAV_SEVERITY_INFO, line)

    def push_heartbeat(self) -> None:
        for link in self.links:
            link.push(M.MAVLINK_MSG_ID_HEARTBEAT)

    def prearm_failures(self) -> list[str]:
        """The pre-arm checks the core knows about; vehicle types add theirs."""
        s = self.state
        failures = []
        if s.gps_fix_type < 3:
            failures.append("GPS: no 3D fix")
        if s.battery_remaining_pct < 10:
            failures.append(f"Battery below minimum ({s.battery_remaining_pct}%)")
        return failures

    def send_pass(self, channel: Channel, now: float) -> float | None:
        """Run this node's scheduler and text queue on one channel; returns the next deadline."""
        self.sim.step(now)
        link = self.links[channel.index]
        sysid, compid = self.sysid, self.compid

        def send(msgid: int) -> bool:
            producer = PRODUCERS.get(msgid)
            if producer is None or not channel.peers:
                return True  # nothing to say, or nobody to say it to: keep the schedule's phase
            msg = producer(self, channel, now)
            if msg is None:
                return True
            if not channel.has_room(msg.unpacker.size + 12):
                return False
            channel.send_message(msg, sysid, compid)
            return True

        def send_text(msg) -> bool:
            if not channel.has_room(MAX_FRAME_BYTES):
                return False
            channel.send_message(msg, sysid, compid)
            return True

        finished = link.scheduler.run(now, send) and self.statustext.drain(channel.index, now, send_text)
        if not finished:
            return now + max(channel.budget_wait_s(), 0.001)
        return link.scheduler.next_deadline(now)
