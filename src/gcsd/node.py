"""A local MAVLink component: one simulated vehicle (sysid, compid) and its services.

The node owns the vehicle state and simulation, one Link (scheduler + stream rates) per
channel, the STATUSTEXT queue, and the dispatch tables built from its services: message name ->
`handle_<NAME>` method, command id -> handler. It handles only what the router says is for it.

Messages from other systems are accepted unless `gcs.enforce_sysid` is set, in which case only
our own sysid and the GCS sysid get through (RADIO_STATUS always does), as MAV_OPTIONS bit 0.
Every part runs inside an error boundary (boundary.py): a handler, each telemetry producer, the
STATUSTEXT queue, each service's timer (`pending`) and the autopilot/simulation step (`step`, run
by the GCS's simulation task, independent of the links). An exception is counted under the
part's name and logged with its traceback (rate-limited); that part is skipped this turn and
everything else carries on.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from .autopilot.attach import attach_services, initial_state
from .autopilot.core import Autopilot
from .boundary import ErrorCounts
from .channel import MAX_FRAME_BYTES, Channel
from .clock import Clock
from .codec import Frame
from .config import Config
from .link import Link
from .msgids import is_radio
from .params import ParamStore
from .persist import WriteBehind
from .services import Incoming
from .services.commands import CommandService
from .services.control import ControlService
from .services.mission import MissionService
from .services.params import ParamService
from .services.rates import RatesService
from .services.statustext import StatusTextQueue
from .services.timesync import TimesyncService
from .streams import PARAM_SUFFIX, STREAM_NAMES
from .telemetry import PRODUCERS
from .vehicles import VehicleType, prearm_failures, vehicle_params

log = structlog.get_logger("gcsd.node")



class VehicleNode:
    def __init__(
        self,
        index: int,
        config: Config,
        vehicle: VehicleType,
        clock: Clock,
        channels: list[Channel],
        wake: Callable[[Channel], None],
        backend=None,
        errors: ErrorCounts | None = None,
    ) -> None:
        vcfg = config.vehicle
        self.index = index
        self.vehicle = vehicle
        self.clock = clock
        self.channels = channels
        self.state_dir = _vehicle_state_dir(config, index)
        self.params = ParamStore(vehicle_params(  # ArduPilot's set for the vehicle type (gcsd.params.defs)
            vehicle, vcfg.sysid + index, config.gcs.sysid, config.gcs.enforce_sysid,
            [dict(ch.config.streams) for ch in channels], vcfg.speedup,
        ))
        self.param_service = ParamService(self, self.params, self.state_dir / "mav.parm" if self.state_dir else None,
                                          clock.now())
        self.param_service.load(config.params_file)
        # write-behind of mav.parm: coalesced, on a worker thread, flushed by close()
        self.errors = errors if errors is not None else ErrorCounts()
        self.param_writer = WriteBehind(self.param_service.save_path, self.param_service, clock.now,
                                        errors=self.errors)
        self.param_service.on_dirty = self.param_writer.kick
        self.params.set("STAT_BOOTCNT", self.params.get("STAT_BOOTCNT") + 1, force=True)
        self.sysid = int(self.params.get("SYSID_THISMAV"))
        self.compid = vcfg.compid
        self.gcs_sysid_config, self.enforce_config = config.gcs.sysid, config.gcs.enforce_sysid
        self.min_interval_ms = max(1, 1250 // int(self.params.get("SCHED_LOOP_RATE")))
        now = clock.now()
        capacity = float(self.params.get("BATT_CAPACITY")) if "BATT_CAPACITY" in self.params else 0.0
        self.state = initial_state(vehicle, vcfg.home, index, capacity)
        self.sim = Autopilot(self, backend, now, vcfg.speedup)  # the vehicle: autopilot over a backend
        self.statustext = StatusTextQueue()
        self._sim_component = "sim" if self.sim.simulated else "backend"
        self._wake = wake
        self.links = [Link(ch, now, self._producible, lambda ch=ch: wake(ch)) for ch in channels]
        self._wire_params(now)
        self.control = ControlService(self)
        self.rates = RatesService(self)
        self.services = [self.control, self.rates, TimesyncService(self), self.param_service]
        table: dict[int, Callable] = {}
        for service in self.services:
            table.update(service.commands())
        table.update({cmd: (lambda req, h=h: h(self, req)) for cmd, h in vehicle.commands.items()})
        self.commands = CommandService(self, table)
        self.services.append(self.commands)
        self._build_dispatch()
        self.mission = MissionService(self, config.mission, self.state_dir)
        self.add_service(self.mission)
        attach_services(self, config)
        self.param_service.save()  # the boot count

    def _build_dispatch(self) -> None:
        self.handlers: dict[str, Callable[[Incoming], None]] = {}
        for service in self.services:
            self.handlers.update(service.message_handlers())
        self._senders = [s for s in self.services if hasattr(s, "pending")]

    def add_service(self, service) -> None:
        """Attach a service (missions, FTP...): its handlers, commands and capabilities."""
        self.services.append(service)
        self.commands.table.update(service.commands())
        self._build_dispatch()

    def _wire_params(self, now: float) -> None:
        """Parameters that act at once; the rest are read where they are used."""
        params = self.params
        for link in self.links:
            for stream in STREAM_NAMES:
                name = f"SR{link.channel.index}_{PARAM_SUFFIX[stream]}"
                if name not in params:  # a stream the vehicle type has no SRn_ parameter for
                    link.set_stream_rate(stream, link.channel.config.streams[stream], now)
                    continue
                link.set_stream_rate(stream, params.get(name), now)
                params.on_change(name, lambda _n, v, i=link.channel.index, stream=stream:
                                 self.links[i].set_stream_rate(stream, v, self.clock.now()))
        self.gcs_sysid = int(params.get("SYSID_MYGCS")) if "SYSID_MYGCS" in params else self.gcs_sysid_config
        self.enforce_gcs_sysid = bool(params.get("SYSID_ENFORCE")) if "SYSID_ENFORCE" in params else self.enforce_config
        params.on_change("SYSID_MYGCS", lambda _n, v: setattr(self, "gcs_sysid", int(v)))
        params.on_change("SYSID_ENFORCE", lambda _n, v: setattr(self, "enforce_gcs_sysid", bool(v)))
        params.on_change("BATT_CAPACITY", lambda _n, v: setattr(self.state, "capacity_mah", float(v)))

    def wake(self, channel: Channel) -> None:
        self._wake(channel)

    def shutdown(self, now: float) -> None:
        """A clean stop is coming while the links are still open: services that can end what they
        are doing with a proper answer (an upload with OPERATION_CANCELLED) do it now."""
        for service in self.services:
            end = getattr(service, "shutdown", None)
            if end is not None:
                try:
                    end(now)
                except Exception:
                    log.exception("shutdown_failed", service=type(service).__name__)

    def close(self) -> None:
        """Flush state at a clean stop (waits for a parameter write in flight, writes the rest)."""
        self.param_writer.flush()

    def sync(self) -> None:
        """Write out changed state now and keep running (SIGHUP)."""
        self.param_writer.sync()

    def counters(self) -> dict[str, int]:
        """This vehicle's counted events for `gcsd status` (its services' and the text queue's)."""
        out = {"statustext_dropped": self.statustext.dropped}
        for service in self.services:
            out.update(service.counters())
        return out

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

    def comm_error_count(self) -> int:
        """SYS_STATUS.errors_comm: frames not sent for lack of budget or buffer, on every channel."""
        return sum(ch.stats.drops for ch in self.channels) & 0xFFFF

    def _producible(self, msgid: int) -> bool:
        return msgid in PRODUCERS and self.vehicle.produces(msgid)

    def attach_link(self, channel: Channel, now: float) -> None:
        """A channel opened at run time (livechannels.py): a link in its slot, at its SRn_ rates
        when the slot has them, else at its configured rates."""
        link = Link(channel, now, self._producible, lambda ch=channel: self._wake(ch))
        for stream in STREAM_NAMES:
            name = f"SR{channel.index}_{PARAM_SUFFIX[stream]}"
            if name in self.params:
                link.set_stream_rate(stream, self.params.get(name), now)
        if channel.index == len(self.links):
            self.links.append(link)
        else:
            self.links[channel.index] = link

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
            and not is_radio(frame.msgid)
        ):
            return
        try:
            handler(Incoming(frame.msg, frame, channel, now))
        except Exception:
            self.errors.failed(f"handler:{name}", now, channel=channel.name, msg=name, sysid=frame.sysid,
                               compid=frame.compid)

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
        for line in self.vehicle.banner(self.params.get):  # as ArduPilot's (gcsd.vehicles.firmware)
            self.send_text(M.MAV_SEVERITY_INFO, line)

    def push_heartbeat(self) -> None:
        for link in self.links:
            link.push(M.MAVLINK_MSG_ID_HEARTBEAT)

    def prearm_failures(self) -> list[str]:
        """The vehicle type's pre-arm checks (gcsd.vehicles.prearm; ARMING_CHECK 0: none)."""
        return prearm_failures(self)

    def step(self, now: float) -> None:
        """Advance the autopilot and its simulation (or the embedding backend) to `now`."""
        try:
            self.sim.step(now)
        except Exception:
            self.errors.failed(self._sim_component, now, sysid=self.sysid)

    def send_pass(self, channel: Channel, now: float) -> float | None:
        """Run this node's scheduler, text queue and service timers on one channel; returns the
        next deadline."""
        link = self.links[channel.index]
        sysid, compid = self.sysid, self.compid
        errors = self.errors

        def send(msgid: int) -> bool:
            producer = PRODUCERS.get(msgid)
            if producer is None or not channel.peers:
                return True  # nothing to say, or nobody to say it to: keep the schedule's phase
            try:
                msg = producer(self, channel, now)
                if msg is None:
                    return True
                if not channel.has_room(msg.unpacker.size + 12):
                    return False
                channel.send_message(msg, sysid, compid)
            except Exception:  # skipped this time; the slot keeps its phase
                errors.failed(f"producer:{M.mavlink_map[msgid].msgname}", now, channel=channel.name, sysid=sysid)
            return True

        def send_text(msg) -> bool:
            if not channel.has_room(MAX_FRAME_BYTES):
                return False
            channel.send_message(msg, sysid, compid)
            return True

        finished = link.scheduler.run(now, send) and self._drain_text(channel, now, send_text)
        if not finished:
            return now + max(channel.budget_wait_s(), 0.001)
        deadline = link.scheduler.next_deadline(now)

        def send_msg(msg) -> bool:
            return channel.send_message(msg, sysid, compid)

        for service in self._senders:
            try:
                d = service.pending(channel, now, send_msg)
            except Exception:
                errors.failed(f"service:{type(service).__name__}", now, channel=channel.name, sysid=sysid)
                continue
            if d is not None and (deadline is None or d < deadline):
                deadline = d
        return deadline

    def _drain_text(self, channel: Channel, now: float, send_text) -> bool:
        try:
            return self.statustext.drain(channel.index, now, send_text)
        except Exception:
            self.errors.failed("statustext", now, channel=channel.name, sysid=self.sysid)
            return True


def _vehicle_state_dir(config: Config, index: int) -> Path:
    """state_dir for a single vehicle; state_dir/vehicle-N for the N-th vehicle of a swarm."""
    if config.vehicle.count == 1:
        return Path(config.state_dir)
    return Path(config.state_dir) / f"vehicle-{index + 1}"
