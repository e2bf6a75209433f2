"""The GCS object: the composition root. It wires channels, the router and the local
components (one VehicleNode per simulated vehicle) and handles no message itself.

Receive path for every good frame on a channel: the channel has it verified first (the signing
check, `verify`; a frame that fails changes nothing but the reject counters, see channel.py),
then here: drop it if the same bytes came in lately on a link of the same redundant group (or on
any channel, with routing.dedup_ms; counted `duplicates`), drop it if it is a frame this daemon
forwarded less than LOOP_WINDOW_S ago (a
forwarding loop, counted `loop_dropped`; dedup.py), mark the channel active (anything but
RADIO_STATUS), ask the router (learn, forward, process locally?), write the raw frame to the
chosen channels (remembering it), then hand the decoded message to the local component(s) it is for. Frames with a bad CRC are dropped and counted, or, on a
`forward_bad_crc` channel, forwarded unchanged as broadcasts and never processed.

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
from gcsd.boundary import ErrorCounts
from gcsd.clock import Clock
from gcsd.config import MAX_CHANNELS, Config
from gcsd.config.schema import LOCAL_TYPE, ChannelConfig
from gcsd.daemon import compose
from gcsd.daemon.livechannels import LiveChannels, load_specs
from gcsd.links.channel import Channel, Peer
from gcsd.links.transport import ChannelStartError
from gcsd.routing.dedup import LOOP_WINDOW_S, RecentFrames
from gcsd.routing.signgate import signed_copy
from gcsd.vehicle.autopilot.core import DEFAULT_SIM_PERIOD_S
from gcsd.vehicle.node import VehicleNode
from gcsd.wire.codec import Frame
from gcsd.wire.msgids import HEARTBEAT as MSG_ID_HEARTBEAT
from gcsd.wire.msgids import is_radio
from gcsd.wire.signing import SAVE_INTERVAL_S

log = structlog.get_logger("gcsd.daemon.daemon")

MSG_ID_SYSTEM_TIME = 2
STATS_INTERVAL_S = 10.0
IDLE_NODE_PASS_S = 0.5  # a node with nothing scheduled still gets a pass this often (its simulation steps)


class GCS:
    def __init__(self, config: Config, clock: Clock | None = None, backend=None, producers: dict | None = None) -> None:
        """`backend(index)`: an embedding program's vehicle in place of the simulation (gcsd.embed);
        `producers`: a telemetry table in place of gcsd.vehicle.telemetry.producers() (tests)."""
        self.config = config
        self.clock = clock or Clock()
        self.errors = ErrorCounts()
        self.active: set[int] = set()
        self.opened: set[int] = set()  # channels open at least once
        self._tried: set[int] = set()  # channels opened or, for a client, tried once
        self.ready = asyncio.Event()  # every server channel bound, every client channel tried
        self.bad_crc_forwarded = 0
        self.rates: dict[str, tuple[float, float]] = {}
        self.taps: list = []  # tap(channel, frame, now) of every accepted frame (compose.py)
        self.loops = RecentFrames(LOOP_WINDOW_S)  # frames forwarded lately: one coming back is a loop
        # routing.dedup_ms: every frame; else the frames of redundant link groups, within LOOP_WINDOW_S
        dedup_ms = config.routing.dedup_ms
        self.dedup = RecentFrames(dedup_ms / 1000 if dedup_ms else LOOP_WINDOW_S)
        self.dedup_all = dedup_ms > 0  # else only the channels of a group (Channel.dedup)
        restored = load_specs(Path(config.state_dir), config.channels)  # channels added at run time
        # channels, signing, tlog, vehicles, router and every callback: the composition root
        compose.build(self, [*config.channels, *(c for _, c in restored)], backend, producers)
        self._wakeups = [asyncio.Event() for _ in self.channels]
        # per channel, when each node next needs a send pass (0: now)
        self._node_due = [[0.0] * len(self.nodes) for _ in self.channels]
        if self.signing_manager.load_error:
            log.error("signing_state_unreadable", error=self.signing_manager.load_error)
        if self.signing_manager.load_repair:
            log.warning("signing_timestamp_repaired", reason=self.signing_manager.load_repair)
        self.started_s = self.clock.now()
        self._by_sysid = {n.sysid: n for n in self.nodes}
        for ch in self.channels:
            ch.dedup = ch.dedup or self.dedup_all
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
        ch = compose.channel(self, index, config)
        ch.dedup = ch.dedup or self.dedup_all
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
        self.active.discard(ch.index)

    def wake(self, channel: Channel) -> None:
        self._wakeups[channel.index].set()

    def wake_node(self, index: int, channel: Channel) -> None:
        self._node_due[channel.index][index] = 0.0
        self._wakeups[channel.index].set()

    # --- receive ---------------------------------------------------------------------------
    def verify(self, channel: Channel, frame: Frame) -> str | None:
        """The signing check, before anything else looks at the frame: None (accepted) or why not."""
        signing = self.signing
        if not signing.checks_needed:
            return None
        return signing.check(frame.raw, frame.msgid, frame.sysid, frame.compid, channel.unsigned_ok,
                             self.clock.wall())

    def on_frame(self, channel: Channel, frame: Frame, now: float) -> None:
        """Route one accepted frame and hand it to the local components it is for (inside the
        channel's receive boundary)."""
        if channel.dedup and self.dedup.check(frame.raw, now):
            channel.stats.duplicates += 1  # the copy that came the other way (a group), or dedup_ms
            return
        if self.loops.seen(frame.raw, now):  # a frame we forwarded, back again: a loop (dedup.py)
            channel.stats.loop_dropped += 1
            return
        if self.taps:
            for tap in self.taps:
                tap(channel, frame, now)
        msgid = frame.msgid
        if channel.index not in self.active and not is_radio(msgid):
            self.active.add(channel.index)
        decision = self.router.decide(
            channel.index, msgid, frame.sysid, frame.compid, frame.target_system, frame.target_component,
            now, self.active, frame.known,
            frame.msg.type if msgid == MSG_ID_HEARTBEAT and frame.known else None,
        )
        if decision.out_channels:
            raw = frame.raw
            if channel.sign_forwarded and self.signing.key is not None:
                raw = self._signed(channel, raw)
            self.loops.remember(raw, now)  # the bytes that go out: what a loop brings back
            channels = self.channels
            for index in decision.out_channels:
                channels[index].out.write(raw)
        if channel.stream_requests is not None and (msgid == MSG_ID_HEARTBEAT or msgid == MSG_ID_SYSTEM_TIME):
            self._request_streams(channel, frame, now)
        if decision.process_locally and frame.known:
            for node in self._nodes_for(frame.target_system, frame.target_component):
                node.handle(channel, frame, now)
                for due in self._node_due:  # whatever it queued goes out at the next pass
                    due[node.index] = 0.0

    def _signed(self, channel: Channel, raw: bytes) -> bytes:
        """The signing gateway: an unsigned frame from a sign_forwarded channel, signed (signgate.py)."""
        signed = signed_copy(raw, self.signing.key, channel.index, self.signing.next_timestamp(self.clock.wall()))
        return raw if signed is None else signed

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

    def reject(self, channel: Channel, frame: Frame, reason: str, now: float) -> None:
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

    def on_bad_crc(self, channel: Channel, raw: bytes) -> None:
        now = self.clock.now()
        if self.loops.seen(raw, now):
            channel.stats.loop_dropped += 1
            return
        self.loops.remember(raw, now)
        for index in self.router.broadcast_channels(channel.index):
            self.channels[index].write(raw)
        self.bad_crc_forwarded += 1

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
            if self.tlog is not None:
                self.tlog.close()

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
            self.signing_writer.sync()  # not "clean": the daemon goes on signing
        log.info("state_synced", vehicles=len(self.nodes))

    def _flush(self) -> None:
        for node in self.nodes:
            try:
                node.close()
            except Exception:
                log.exception("flush_failed", sysid=node.sysid)
        self.signing_writer.flush()
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
            self.wake_time.now, self.wake_time.wall = now, self.clock.wall()
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
                self.signing_writer.kick()  # written on the write-behind's worker thread
                if self.signing_manager.save_error:
                    log.error("signing_save_failed", error=self.signing_manager.save_error)

    async def _log_stats(self) -> None:
        last = {ch: ch.snapshot() for ch in self.channels}
        while True:
            for _ in range(int(STATS_INTERVAL_S)):
                await asyncio.sleep(1.0)
                if self.tlog is not None:
                    with self.errors.guard("tlog", self.clock.now()):
                        self.tlog.flush()
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
