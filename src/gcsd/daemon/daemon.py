"""The daemon: it runs the parts compose.build made (channels, router, ingress, vehicles) and
applies what the ingress decides for each frame; it handles no message itself.

Receive path for every good frame on a channel (links/channel.py parses it and admits its peer):
the signing check (`verify`, routing/ingress.py; a frame that fails changes nothing but the
reject counters), the channel's input filter, then `on_frame`: the ingress decides the frame's
fate (duplicate, loop, or where it goes, whether it is signed by the gateway, handled here,
shown to the taps, answered with a stream request), and this applies it: taps, writes to the
chosen channels' outboxes, the stream request, the local components' handlers. Frames with a
bad CRC are dropped and counted, or, on a `forward_bad_crc` channel, forwarded unchanged as
broadcasts and never processed.

Tasks (one TaskGroup): one per channel (receive in callbacks, send passes), the simulation (every
node's autopilot and simulation or embedding backend, SIM_RATE_HZ, whether or not any link is
up), the stats log and the signing timestamp saver. Every part runs inside an error boundary
(boundary.py): one `ErrorCounts` per daemon, shown by `gcsd status`.

Send passes: each vehicle node says when it next needs one on a channel (its deadline); a
channel's pass runs only the nodes that are due, that were woken (something queued) or that
just handled a frame, so a swarm of a hundred vehicles costs what their messages cost, not a
hundred schedulers per pass. `backend` (gcsd.embed) replaces each node's simulation.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.api import control, status
from gcsd.api.http import wiring as http_wiring
from gcsd.boundary import ErrorCounts
from gcsd.clock import Clock
from gcsd.config import MAX_CHANNELS, Config
from gcsd.config.schema import LOCAL_TYPE, ChannelConfig
from gcsd.daemon import compose
from gcsd.daemon.livechannels import LiveChannels, load_specs
from gcsd.links.channel import Channel, Peer
from gcsd.links.transport import ChannelStartError
from gcsd.routing.authority import refusal_message, role_name
from gcsd.routing.ingress import DENIED
from gcsd.vehicle.autopilot.core import DEFAULT_SIM_PERIOD_S
from gcsd.vehicle.node import VehicleNode
from gcsd.vehicle.params.store import as_float
from gcsd.wire.codec import Frame
from gcsd.wire.msgids import HEARTBEAT as MSG_ID_HEARTBEAT
from gcsd.wire.signing import SAVE_INTERVAL_S

log = structlog.get_logger("gcsd.daemon.daemon")

STATS_INTERVAL_S = 10.0
IDLE_NODE_PASS_S = 0.5  # a node with nothing scheduled still gets a pass this often (its simulation steps)


class Daemon:
    def __init__(self, config: Config, clock: Clock | None = None, backend=None, producers: dict | None = None) -> None:
        """`backend(index)`: an embedding program's vehicle in place of the simulation (gcsd.embed);
        `producers`: a telemetry table in place of gcsd.vehicle.telemetry.producers() (tests)."""
        self.config = config
        self.clock = clock or Clock()
        self.errors = ErrorCounts()
        self.opened: set[int] = set()  # channels open at least once
        self._tried: set[int] = set()  # channels opened or, for a client, tried once
        self.ready = asyncio.Event()  # every server channel bound, every client channel tried
        self.rates: dict[str, tuple[float, float]] = {}
        restored = load_specs(Path(config.state_dir), config.channels)  # channels added at run time
        parts = compose.build(config, self.clock, self.errors, self,
                              [*config.channels, *(c for _, c in restored)], self.wake_node, backend, producers)
        self.parts = parts
        self.channels, self.nodes, self.router, self.ingress = parts.channels, parts.nodes, parts.router, parts.ingress
        self.signing_manager, self.signing = parts.signing_manager, parts.signing_manager.signing
        self.taps = list(parts.taps)
        self.http = http_wiring.attach(self)  # the HTTP API over all of it, or None (`http.address: null`)
        if self.http is not None:
            self.taps.append(self.http.tap)  # its message tree takes every accepted frame
        self._wakeups = [asyncio.Event() for _ in self.channels]
        # per channel, when each node next needs a send pass (0: now)
        self._node_due = [[0.0] * len(self.nodes) for _ in self.channels]
        if self.signing_manager.load_error:
            log.error("signing_state_unreadable", error=self.signing_manager.load_error)
        if self.signing_manager.load_repair:
            log.warning("signing_timestamp_repaired", reason=self.signing_manager.load_repair)
        self.started_s = self.clock.now()
        self._by_sysid = {n.sysid: n for n in self.nodes}
        self.live = LiveChannels(self, restored)

    # --- channels at run time (livechannels.py) ------------------------------------------------
    def free_slot(self, prefer: int | None = None) -> int | None:
        """The slot for a channel added at run time: `prefer` or the lowest retired one, or a new one."""
        retired = [ch.index for ch in self.channels if ch.retired]
        if prefer in retired:
            return prefer
        if retired:
            return retired[0]
        mavlink = sum(1 for ch in self.channels if ch.config.type != LOCAL_TYPE)  # the HTTP API's takes no slot
        return len(self.channels) if mavlink < MAX_CHANNELS else None

    def attach(self, index: int, config: ChannelConfig) -> Channel:
        """A new channel in slot `index`: wired, known to the router and to every vehicle."""
        ch = compose.channel(self.parts.channel_parts, index, config)
        if index == len(self.channels):
            self.channels.append(ch)
            self._wakeups.append(asyncio.Event())
            self._node_due.append([0.0] * len(self.nodes))
        else:
            self.channels[index] = ch
            self._wakeups[index] = asyncio.Event()
            self._node_due[index] = [0.0] * len(self.nodes)
        self.router.set_policy(index, ch.policy)
        now = self.clock.now()
        for node in self.nodes:
            node.attach_link(ch, now)
        return ch

    def detach(self, ch: Channel) -> None:
        """A channel closed at run time: no peers, no routes; its slot waits for the next one."""
        ch.drop_all_peers()
        ch.retired = True
        self.router.table.forget_channel(ch.index)
        self.ingress.active.discard(ch.index)

    def wake(self, channel: Channel) -> None:
        self._wakeups[channel.index].set()

    def wake_node(self, index: int, channel: Channel) -> None:
        self._node_due[channel.index][index] = 0.0
        self._wakeups[channel.index].set()

    # --- receive: links.channel.Receiver ---------------------------------------------------
    @property
    def active(self) -> set[int]:
        return self.ingress.active

    @property
    def bad_crc_forwarded(self) -> int:
        return self.ingress.bad_crc_forwarded

    def verify(self, channel: Channel, frame: Frame) -> str | None:
        """The signing check, before anything else looks at the frame: None (accepted) or why not."""
        return self.ingress.verify(channel, frame, channel.out.time.wall)

    def on_frame(self, channel: Channel, frame: Frame, now: float) -> None:
        """Apply the ingress's decision on one accepted frame (inside the channel's receive boundary)."""
        fate = self.ingress.decide(channel, frame, now)
        if fate.drop is not None:
            setattr(channel.stats, fate.drop, getattr(channel.stats, fate.drop) + 1)
            if fate.drop == DENIED:
                self._refuse(channel, frame, fate.refuse)
            return
        for tap in self.taps:
            tap(channel, frame, now)
        if fate.forward:
            raw = self.ingress.signed(channel, frame.raw, now, channel.out.time.wall) if fate.sign else frame.raw
            channels = self.channels
            for index in fate.forward:
                channels[index].out.write(raw)
        if fate.streams:
            self._request_streams(channel, frame, now)
        if fate.local:
            for node in self._nodes_for(frame.target_system, frame.target_component):
                node.handle(channel, frame, now)
                for due in self._node_due:  # whatever it queued goes out at the next pass
                    due[node.index] = 0.0

    def _refuse(self, channel: Channel, frame: Frame, kind: str | None) -> None:
        """A denied frame (routing/authority.py): the protocol's refusal from the vehicle it was
        meant for (or the first), and a log line with who."""
        key = self.signing.verified_by
        log.warning("denied", channel=channel.name, sysid=frame.sysid, compid=frame.compid, msg=frame.name,
                    key=None if key is None else key.name, role=role_name(self.ingress.last_role))
        nodes = self._nodes_for(frame.target_system, frame.target_component) or self.nodes
        node = nodes[0]
        msg = frame.msg if frame.known else None

        def param(name: str):
            entry = node.params.entry_by_name(name)
            if entry is None:
                return None
            return M.MAVLink_param_value_message(entry.name.encode(), as_float(entry.value), entry.ptype,
                                                 len(node.params), entry.index)

        answer = refusal_message(kind, msg, frame.sysid, frame.compid, param)
        if answer is not None:
            node.reply(channel, answer)

    def _request_streams(self, channel: Channel, frame: Frame, now: float) -> None:
        """request_streams: REQUEST_DATA_STREAM to an autopilot first heard or rebooted (streamreq.py)."""
        msg, requests = frame.msg, channel.stream_requests
        if msg is None:
            return
        if frame.msgid == MSG_ID_HEARTBEAT:
            ask = requests.heartbeat(frame.sysid, frame.compid, msg.type, msg.autopilot, now)
        else:
            ask = requests.system_time(frame.sysid, frame.compid, msg.time_boot_ms)
        if ask:
            log.info("streams_requested", channel=channel.name, sysid=frame.sysid, compid=frame.compid,
                     rate_hz=requests.rate_hz)
            node = self.nodes[0]
            channel.send_message(M.MAVLink_request_data_stream_message(
                frame.sysid, frame.compid, M.MAV_DATA_STREAM_ALL, requests.rate_hz, 1),
                node.sysid, node.compid)

    def _nodes_for(self, target_system: int, target_component: int) -> list[VehicleNode]:
        if target_system > 0:
            node = self._by_sysid.get(target_system)
            return [node] if node is not None else []
        if target_component > 0:
            return [n for n in self.nodes if n.compid == target_component] or self.nodes
        return self.nodes

    def on_reject(self, channel: Channel, frame: Frame, reason: str, now: float) -> None:
        """A frame that failed the signing checks: counted, never learned, forwarded or handled."""
        channel.stats.signature_rejects += 1
        channel.signature_reject_reasons[reason] = channel.signature_reject_reasons.get(reason, 0) + 1
        if self.signing_manager.should_warn(channel.index, now):
            log.warning("signature_rejected", channel=channel.name, sysid=frame.sysid, compid=frame.compid,
                        msg=frame.name, reason=reason)
            for node in self.nodes:
                node.text(M.MAV_SEVERITY_WARNING, f"Signing: rejected packet ({reason})", channels={channel.index})

    def on_peer_joined(self, channel: Channel, peer: Peer) -> None:
        """A new ground station hears from us at once instead of at the next 1 Hz slot."""
        log.info("peer_joined", channel=channel.name, peer=_peer_name(peer.key))
        for node in self.nodes:
            node.link(channel).push(MSG_ID_HEARTBEAT)

    def on_bad_crc(self, channel: Channel, raw: bytes, now: float) -> None:
        out = self.ingress.bad_crc(channel, raw, now)
        if out is None:
            channel.stats.loop_dropped += 1
            return
        for index in out:
            self.channels[index].write(raw)

    # --- send ------------------------------------------------------------------------------
    def send_pass(self, channel: Channel, now: float) -> float | None:
        for gone in channel.sweep(now):
            log.info("peer_forgotten", channel=channel.name, peer=_peer_name(gone))
        deadline = None
        due = self._node_due[channel.index]
        for index, node in enumerate(self.nodes):
            if due[index] <= now:
                try:
                    d = node.send_pass(channel, now)
                except Exception:  # noqa: BLE001  (one vehicle's send pass must not stop the channel's)
                    self.errors.failed("send_pass", now, channel=channel.name, sysid=node.sysid)
                    d = None
                due[index] = d if d is not None else now + IDLE_NODE_PASS_S
            if deadline is None or due[index] < deadline:
                deadline = due[index]
        return deadline

    # --- run -------------------------------------------------------------------------------
    def _opened(self, channel: Channel, ok: bool) -> None:
        if ok:
            self.opened.add(channel.index)
        self._tried.add(channel.index)
        if len(self._tried) == len(self.channels):
            self.ready.set()

    async def run(self, stop: asyncio.Event) -> None:
        """Serve every channel until `stop` is set."""
        sock_path = Path(self.config.state_dir) / control.SOCKET_NAME
        try:
            server = await control.serve(sock_path, self.status, {
                "channel_add": lambda request: self.live.add(request.get("spec")),
                "channel_remove": lambda request: self.live.remove(str(request.get("name"))),
            }, lambda cmd: self.errors.failed(f"control:{cmd}", self.clock.now()))
        except OSError as exc:
            server = None
            log.error("control_socket_failed", path=str(sock_path), error=str(exc))
        try:
            await self._serve(stop)
        finally:
            if server is not None:
                server.close()
                sock_path.unlink(missing_ok=True)
            if self.parts.tlog is not None:
                self.parts.tlog.close()

    async def _serve(self, stop: asyncio.Event) -> None:
        try:
            await self._serve_tasks(stop)
        except* ChannelStartError as group:
            raise group.exceptions[0] from None
        finally:  # whatever ended the serving, what was changed is written out
            self._flush()

    def sync_state(self) -> None:
        """Write out what was changed (parameters, the signing timestamp) and keep running: SIGHUP
        does this before it re-reads the configuration, so nothing acknowledged waits on a timer
        while channels are reopened (app.py)."""
        now = self.clock.now()
        for node in self.nodes:
            with self.errors.guard("sync", now, sysid=node.sysid):
                node.sync()
        with self.errors.guard("sync", now):
            self.parts.signing_writer.sync()  # not "clean": the daemon goes on signing
        log.info("state_synced", vehicles=len(self.nodes))

    def _flush(self) -> None:
        for node in self.nodes:
            try:
                node.close()
            except Exception:
                log.exception("flush_failed", sysid=node.sysid)
        self.parts.signing_writer.flush()
        if self.signing.key is not None:
            try:
                self.signing_manager.save(clean=True)
            except OSError as exc:
                log.error("signing_save_failed", error=str(exc))

    async def _serve_tasks(self, stop: asyncio.Event) -> None:
        async with asyncio.TaskGroup() as tg:
            self.live.start(tg)
            tasks = [tg.create_task(self._simulate(), name="simulation")]
            tasks.append(tg.create_task(self._log_stats(), name="stats"))
            tasks.append(tg.create_task(self._save_signing_timestamp(), name="signing"))
            await stop.wait()
            now = self.clock.now()
            self.parts.wake_time.now, self.parts.wake_time.wall = now, self.clock.wall()
            for node in self.nodes:
                node.shutdown(now)  # final answers go out while the links are still open
            await asyncio.sleep(0.05)  # let stream transports write them
            for task in [*tasks, *self.live.tasks.values()]:
                task.cancel()

    async def _simulate(self) -> None:
        """Every node's autopilot and simulation, links or no links (failsafes need it most when
        the only link is down)."""
        while True:
            now = self.clock.now()
            for node in self.nodes:
                node.step(now)  # guarded inside
            period = min((n.autopilot.period_s for n in self.nodes), default=DEFAULT_SIM_PERIOD_S)
            await asyncio.sleep(max(0.001, period - (self.clock.now() - now)))

    async def _save_signing_timestamp(self) -> None:
        while True:
            await asyncio.sleep(SAVE_INTERVAL_S)
            with self.errors.guard("signing_save", self.clock.now()):
                self.parts.signing_writer.kick()  # written on the write-behind's worker thread
                if self.signing_manager.save_error:
                    log.error("signing_save_failed", error=self.signing_manager.save_error)

    async def _log_stats(self) -> None:
        last = {ch: ch.snapshot() for ch in self.channels}
        while True:
            for _ in range(int(STATS_INTERVAL_S)):
                await asyncio.sleep(1.0)
                if self.parts.tlog is not None:
                    with self.errors.guard("tlog", self.clock.now()):
                        self.parts.tlog.flush()
            with self.errors.guard("stats", self.clock.now()):
                self._stats_pass(last)

    def _stats_pass(self, last: dict[Channel, dict[str, int]]) -> None:
        """The 10-second stats line and the packet rates `gcsd status` shows."""
        for ch in self.live.running():
            snap = ch.snapshot()
            prev = last.get(ch, snap)
            self.rates[ch.name] = (
                (snap["packets_in"] - prev["packets_in"]) / STATS_INTERVAL_S,
                (snap["packets_out"] - prev["packets_out"]) / STATS_INTERVAL_S,
            )
            last[ch] = snap
            log.info("channel_stats", channel=ch.name, **snap)
        log.info("routes_learned", routes=len(self.router.table), not_learned=self.router.table.not_learned)

    def stats(self) -> dict[str, dict[str, int]]:
        return {ch.name: ch.snapshot() for ch in self.live.running()}

    def status(self) -> dict:
        """Everything `gcsd status` shows (status.py, control.py)."""
        return status.document(self)

    def counters(self) -> dict[str, int]:
        return status.counters(self)


def _peer_name(key: object) -> str:
    return f"{key[0]}:{key[1]}" if isinstance(key, tuple) and len(key) == 2 else str(key)
