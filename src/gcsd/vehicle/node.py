"""A local MAVLink component: one vehicle (sysid, compid), its links and its dispatch.

The node implements the `ServiceContext` its services see (context.py): identity, parameters,
state, the autopilot and the control and plan ports, and the effects (reply, text, push,
wake). It owns one Link (scheduler + stream rates) per channel and the STATUSTEXT queue. What
it handles and what it runs is given to it by the composition root (compose.py): the services,
the message and command tables built from them, and the telemetry producers. It handles only
what the router says is for it.

Messages from other systems are accepted unless `gcs.enforce_sysid` is set, in which case only
our own sysid and the GCS sysid get through (RADIO_STATUS always does), as MAV_OPTIONS bit 0.
Every part runs inside the error boundary (boundary.py): a message handler, each command
handler (services/commands.py), each telemetry producer, the STATUSTEXT queue, each service's
timer (`pending`) and the autopilot/simulation step (`step`, run by the GCS's simulation task,
independent of the links). An exception is counted under the part's name and logged with its
traceback (rate-limited); that part is skipped this turn and everything else carries on.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.boundary import ErrorCounts
from gcsd.clock import Clock
from gcsd.config.schema import mavlink_slot
from gcsd.links.channel import Channel
from gcsd.links.link import Link
from gcsd.vehicle.params import ParamStore
from gcsd.vehicle.services import Incoming
from gcsd.vehicle.services.statustext import StatusTextQueue
from gcsd.vehicle.sim.state import VehicleState
from gcsd.vehicle.types import VehicleType, prearm_failures
from gcsd.wire.codec import MAX_FRAME_BYTES, Frame
from gcsd.wire.msgids import is_radio
from gcsd.wire.streams import PARAM_SUFFIX, STREAM_NAMES

log = structlog.get_logger("gcsd.vehicle.node")


class VehicleNode:
    """One vehicle: the ServiceContext of its services, its links and its dispatch."""

    def __init__(self, index: int, vehicle: VehicleType, clock: Clock, channels: list[Channel],
                 params: ParamStore, state: VehicleState, compid: int, state_dir: Path,
                 wake: Callable[[Channel], None], errors: ErrorCounts, producers: dict,
                 save_params: Callable[[], None] = lambda: None) -> None:
        self.index = index
        self.vehicle = vehicle
        self.clock = clock
        self.channels = channels
        self.state_dir = state_dir
        self.params = params
        self.state = state
        self.errors = errors
        self.sysid = int(params.get("SYSID_THISMAV"))
        self.compid = compid
        self.gcs_sysid = 255
        self.enforce_gcs_sysid = False
        self.min_interval_ms = max(1, 1250 // int(params.get("SCHED_LOOP_RATE")))
        self.statustext = StatusTextQueue()
        self._wake = wake
        self._save_params = save_params
        self.producers = producers  # msgid -> producer(view, channel, now) (telemetry/producers.py)
        now = clock.now()
        self.links = [Link(ch, now, self.producible, lambda ch=ch: wake(ch)) for ch in channels]
        # set by the composition root before the first frame or pass
        self.autopilot = None
        self.control = None
        self.plans = None
        self.services: list = []
        self.handlers: dict[str, Callable[[Incoming], None]] = {}
        self.flushers: list[Callable[[], None]] = []  # write-behinds flushed by close()
        self.syncers: list[Callable[[], None]] = []  # and written out now by sync() (SIGHUP)
        self._senders: list = []
        self._sim_component = "sim"
        self.registry = None  # compose.Registry: who registered which id
        self.local_compids: list[int] = []  # other components of this system its services speak for

    def attach(self, services: list, handlers: dict[str, Callable[[Incoming], None]]) -> None:
        """The composition root's last step: the services and the message table built from them."""
        self.services = list(services)
        self.handlers = handlers
        self._senders = [s for s in self.services if hasattr(s, "pending")]
        self._sim_component = "sim" if self.autopilot.simulated else "backend"

    def shutdown(self, now: float) -> None:
        """A clean stop is coming while the links are still open: services that can end what they
        are doing with a proper answer (an upload with OPERATION_CANCELLED) do it now."""
        for service in self.services:
            end = getattr(service, "shutdown", None)
            if end is not None:
                with self.errors.guard(f"shutdown:{type(service).__name__}", now, sysid=self.sysid):
                    end(now)

    def close(self) -> None:
        """Flush state at a clean stop (waits for a write in flight, writes the rest)."""
        for flush in self.flushers:
            flush()

    def sync(self) -> None:
        """Write out changed state now and keep running (SIGHUP)."""
        for sync in self.syncers:
            sync()

    # --- the ServiceContext ------------------------------------------------------------------
    def now(self) -> float:
        return self.clock.now()

    def wall(self) -> float:
        return self.clock.wall()

    def time_boot_ms(self, now: float) -> int:
        return int(self.clock.since_boot(now) * 1000) & 0xFFFFFFFF

    def time_usec(self, now: float) -> int:
        return int(self.clock.since_boot(now) * 1e6)

    def link(self, channel: Channel) -> Link:
        return self.links[channel.index]

    def reply(self, channel: Channel, msg) -> bool:
        """Answer on one channel: now, or queued until its byte budget has room (outbox.py)."""
        out = channel.out
        sent = out.reply(msg, self.sysid, self.compid)
        if out.replies:
            self._wake(channel)  # the next pass sends it when the budget has refilled
        return sent

    def text_channels(self) -> set[int]:
        """Where STATUSTEXT goes: served links that are not private."""
        return {
            link.channel.index
            for link in self.links
            if not link.channel.policy.private and link.channel.peers
        }

    def text(self, severity: int, text: str, channels: set[int] | None = None) -> None:
        targets = self.text_channels() if channels is None else channels
        self.statustext.add(severity, text, targets, self.clock.now())
        for index in targets:
            self._wake(self.channels[index])

    def push(self, msgid: int) -> None:
        for link in self.links:
            link.push(msgid)

    def set_slow(self, channel: Channel, reason: str, active: bool) -> None:
        self.links[channel.index].set_slow(reason, active)

    def wake(self, channel: Channel) -> None:
        self._wake(channel)

    def banner(self) -> None:
        for line in self.vehicle.banner(self.params.get):  # as ArduPilot's (gcsd.vehicle.types.firmware)
            self.text(M.MAV_SEVERITY_INFO, line)

    def prearm_failures(self) -> list[str]:
        """The vehicle type's pre-arm checks (gcsd.vehicle.types.prearm; ARMING_CHECK 0: none)."""
        return prearm_failures(self)

    def save_params(self) -> None:
        self._save_params()

    # --- what telemetry reads besides the context ----------------------------------------------
    def capabilities(self) -> int:
        caps = self.vehicle.capabilities
        for service in self.services:
            caps |= service.capabilities
        return caps

    def comm_error_count(self) -> int:
        """SYS_STATUS.errors_comm: frames not sent for lack of budget or buffer, on every channel."""
        return sum(ch.stats.drops for ch in self.channels) & 0xFFFF

    def producible(self, msgid: int) -> bool:
        """Whether `msgid` goes into this vehicle's streams."""
        return msgid in self.producers and self.vehicle.streams(msgid)

    def attach_link(self, channel: Channel, now: float) -> None:
        """A channel opened at run time (livechannels.py): a link in its place, at the SRn_ rates
        of its MAVLink slot n when the vehicle has them, else at its configured rates."""
        link = Link(channel, now, self.producible, lambda ch=channel: self._wake(ch))
        slot = mavlink_slot([ch.config.type for ch in self.channels], channel.index)
        for stream in STREAM_NAMES:
            name = f"SR{slot}_{PARAM_SUFFIX[stream]}"
            if name in self.params:
                link.set_stream_rate(stream, self.params.clamped(name), now)
        if channel.index == len(self.links):
            self.links.append(link)
        else:
            self.links[channel.index] = link

    def set_slot_rate(self, slot: int, stream: str, rate_hz: float, now: float) -> None:
        """An SRn_ parameter changed: the rate of the channel in MAVLink slot n, if one is open."""
        types = [ch.config.type for ch in self.channels]
        for link in self.links:
            if not link.channel.retired and mavlink_slot(types, link.channel.index) == slot:
                link.set_stream_rate(stream, rate_hz, now)

    def counters(self) -> dict[str, int]:
        """This vehicle's counted events for `gcsd status` (its services' and the text queue's)."""
        out = {"statustext_dropped": self.statustext.dropped}
        for service in self.services:
            out.update(service.counters())
        return out

    # --- receive ---------------------------------------------------------------------------
    def handle(self, channel: Channel, frame: Frame, now: float) -> None:
        name = frame.name
        handler = self.handlers.get(name)
        if handler is None:
            return
        if (
            self.enforce_gcs_sysid
            and frame.sysid not in (self.gcs_sysid, self.sysid)
            and not is_radio(frame.msgid)
        ):
            return
        try:
            handler(Incoming(frame.msg, frame, channel, now))
        except Exception:  # noqa: BLE001  (a service's error boundary: counted, the channel goes on)
            self.errors.failed(f"handler:{name}", now, channel=channel.name, msg=name, sysid=frame.sysid,
                               compid=frame.compid)

    # --- send ------------------------------------------------------------------------------
    def step(self, now: float) -> None:
        """Advance the autopilot and its simulation (or the embedding backend) to `now`."""
        try:
            self.autopilot.step(now)
        except Exception:  # noqa: BLE001  (the simulation's boundary: counted, stepped again next time)
            self.errors.failed(self._sim_component, now, sysid=self.sysid)

    def send_pass(self, channel: Channel, now: float) -> float | None:
        """Run this node's scheduler, text queue and service timers on one channel; returns the
        next deadline. The order (scheduler.py, "The pass"): queued replies (while some remain,
        nothing else but the streams); HEARTBEAT and pushed messages; STATUSTEXT, then each
        service's `pending`; the replies, the text and the services all within their ServiceShare
        of the byte budget while streams are due; then the stream buckets, unless one of them is
        waiting for the budget to refill within its share (for HOLD_MAX_S at most)."""
        link = self.links[channel.index]
        scheduler = link.scheduler
        sysid, compid = self.sysid, self.compid
        errors, producers = self.errors, self.producers
        out = channel.out  # the only writer (outbox.py): asked directly, one hop fewer per message
        has_room, send_message = out.has_room, out.send_message

        def send(msgid: int) -> bool:
            producer = producers.get(msgid)
            if producer is None or not channel.peers:
                return True  # nothing to say, or nobody to say it to: keep the schedule's phase
            try:
                msg = producer(self, channel, now)
                if msg is None:
                    return True
                if not has_room(msg.unpacker.size + 12):
                    return False
                send_message(msg, sysid, compid)
            except Exception:  # noqa: BLE001  (skipped this time; the slot keeps its phase)
                errors.failed(f"producer:{M.mavlink_map[msgid].msgname}", now, channel=channel.name, sysid=sysid)
            return True

        share = link.share
        if share is not None:
            share.begin(enforced=scheduler.streams_due(now))
        deadline = self._flush_replies(out, share, now)  # replies owed first, then the rest
        if deadline is None:
            if not scheduler.run_urgent(now, send):
                return now + max(out.budget_wait_s(), 0.001)
            deadline = self._services_turn(channel, now, share)
        if share is not None and share.holds_streams(now):  # owed traffic waits for a whole frame
            streams = now + max(out.budget_wait_s(), 0.001)
        elif scheduler.run_streams(now, send):
            streams = scheduler.next_deadline(now)
        else:
            streams = now + max(out.budget_wait_s(), 0.001)
        if streams is not None and (deadline is None or streams < deadline):
            deadline = streams
        return deadline

    @staticmethod
    def _flush_replies(out, share, now: float) -> float | None:
        """The queued replies, within `share` as the services' turn; None when all went out, else
        when to try again."""
        if not out.replies:
            return None
        out.share = share
        try:
            return None if out.flush_replies() else now + max(out.budget_wait_s(), 0.001)
        finally:
            out.share = None

    def _services_turn(self, channel: Channel, now: float, share) -> float | None:
        """STATUSTEXT, then every service's `pending`, charged to `share` (and within it while
        the streams are due) on a link with a byte budget."""
        out = channel.out
        sysid, compid, errors = self.sysid, self.compid, self.errors
        send_message = out.send_message

        def send_text(msg) -> bool:
            if not out.has_room(MAX_FRAME_BYTES):
                return False
            send_message(msg, sysid, compid)
            return True

        def send_msg(msg) -> bool:
            return send_message(msg, sysid, compid)

        out.share = share
        try:
            deadline = None if self._drain_text(channel, now, send_text) else now + max(out.budget_wait_s(), 0.001)
            for service in self._senders:
                try:
                    d = service.pending(channel, now, send_msg)
                except Exception:  # noqa: BLE001  (a service's error boundary: counted, the others still send)
                    errors.failed(f"service:{type(service).__name__}", now, channel=channel.name, sysid=sysid)
                    continue
                if d is not None and (deadline is None or d < deadline):
                    deadline = d
        finally:
            out.share = None
        return deadline

    def _drain_text(self, channel: Channel, now: float, send_text) -> bool:
        try:
            return self.statustext.drain(channel.index, now, send_text)
        except Exception:  # noqa: BLE001  (the text queue's boundary: counted, the pass goes on)
            self.errors.failed("statustext", now, channel=channel.name, sysid=self.sysid)
            return True

