"""Flight logs on a node: the thin adapter between the node and the pure cores.

- **Serving** (transfer.py): LOG_REQUEST_LIST, LOG_REQUEST_DATA, LOG_REQUEST_END and LOG_ERASE
  from a ground station (addressed to this vehicle, component 0 included; on a companion computer,
  which shares its sysid with the flight controller, to its own component only, so the two never
  both answer) start or end that requester's `LogTransfer` (at most MAX_TRANSFERS, the
  oldest idle one makes room). While the vehicle is armed they are ignored, with one "Disarm for
  log download" STATUSTEXT, as ArduPilot. LOG_ENTRY and LOG_DATA go out in the node's send pass
  (`pending`), at most PACKETS_PER_PASS per pass, only while the link's byte budget has room,
  and on a link with a configured bandwidth no faster than 1/BANDWIDTH_SHARE of it, so
  telemetry and the client's own requests keep their room. Reads are 4 KiB preads (a cached
  window per transfer); LOG_ERASE deletes every log that is not being written.
- **Simulated log** (simlog.py; `simulated` and a simulated vehicle): arming starts a new `.BIN`
  (header, banner, parameters, mode); while armed and DISARMED_TAIL_S after disarming, samples
  are appended at the recorder's rate (`tick`, run from the send passes: its deadline is the
  next sample); then the file is finished off the loop (fsync).
- **Capture** (capture.py; `capture`, node 0 only): HEARTBEAT and SYSTEM_TIME of flight
  controllers (a tap: every accepted frame, before routing; only a capturing service has one)
  and REMOTE_LOG_DATA_BLOCK addressed to us go to the core; its REMOTE_LOG_BLOCK_STATUS answers are sent on the flight
  controller's channel at once, its writes go to the store. A block that cannot be written
  (min_free_mb reached and nothing left to rotate) is counted in `write_refused` and still ACKed.

Counters (`counters()`, shown by `gcsd status` as `logs_*`): lists answered, bytes served, logs
erased, requests refused while armed, writes refused; with capture, `logs_capture_*`: blocks,
duplicates, recovered, abandoned, ignored, logs, starts and NACKs sent.
"""

from __future__ import annotations

from dataclasses import dataclass

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.links.channel import MAX_FRAME_BYTES
from gcsd.payloads.logs.capture import Capture, Close, Open, Status, Write
from gcsd.payloads.logs.fastpack import LogData
from gcsd.payloads.logs.simlog import FlightRecorder
from gcsd.payloads.logs.store import READ_MAX, LogFile, LogStore, finish_off_loop
from gcsd.payloads.logs.transfer import Chunk, EntryMsg, LogTransfer
from gcsd.vehicle.services import Incoming, Service

log = structlog.get_logger("gcsd.payloads.logs")

MAX_TRANSFERS = 8
PACKETS_PER_PASS = 64
BANDWIDTH_SHARE = 2  # log data uses at most half of a link's configured bandwidth
DISARMED_TAIL_S = 2.0  # ArduPilot logs 15 s past disarming; a simulated log settles sooner
LOG_DATA_FRAME_BYTES = 12 + 97 + 13  # header, payload, signature


@dataclass
class LogCounters:
    lists: int = 0
    bytes_served: int = 0
    erased: int = 0
    write_refused: int = 0
    refused_armed: int = 0


@dataclass
class _Served:
    transfer: LogTransfer
    channel_index: int  # the requester's channel (by slot: a channel reopened in place keeps it)
    window: tuple[str, int, bytes] = ("", 0, b"")  # name, offset, data read ahead
    next_send_s: float = 0.0
    touched_s: float = 0.0


class FlightLogService(Service):
    def __init__(self, node, store: LogStore, simulated: bool, capture: Capture | None,
                 exact_component: bool = False) -> None:
        self.node = node
        self.exact_component = exact_component  # a companion: only requests addressed to its compid
        self.store = store
        self.capture = capture
        self.recorder = FlightRecorder(node.vehicle.modes) if simulated else None
        self.counters_ = LogCounters()
        self._served: dict[tuple[int, int, int], _Served] = {}
        self._warned_armed = False
        self._sim_file: LogFile | None = None
        self._disarmed_s: float | None = None
        self._captured: dict[int, LogFile] = {}  # capture key -> file
        self._captured_names: dict[int, tuple[str, float]] = {}  # key -> (file, start)
        self._capture_channels: dict[int, object] = {}
        if capture is not None:  # a tap costs every frame of every channel: only where it is needed
            self.tap = self._tap
        try:
            store.ensure()
        except OSError as exc:  # preflight refuses this for `gcsd run`; an embedding program may not check
            log.error("flight_log_dir_unusable", dir=str(store.directory), error=str(exc))

    # --- serving ---------------------------------------------------------------------------
    def _transfer(self, inc: Incoming) -> _Served | None:
        if self.node.state.armed:
            self.counters_.refused_armed += 1
            if not self._warned_armed:
                self._warned_armed = True
                self.node.text(M.MAV_SEVERITY_ERROR, "Disarm for log download", {inc.channel.index})
            return None
        self._warned_armed = False
        key = (inc.channel.index, *inc.sender)
        served = self._served.get(key)
        if served is None:
            if len(self._served) >= MAX_TRANSFERS:
                oldest = min(self._served, key=lambda k: (self._served[k].transfer.busy, self._served[k].touched_s))
                del self._served[oldest]
            served = self._served[key] = _Served(LogTransfer(), inc.channel.index)
        served.touched_s = inc.now
        return served

    def _for_us(self, msg) -> bool:
        compid = self.node.compid
        if self.exact_component:
            return msg.target_system == self.node.sysid and msg.target_component == compid
        return msg.target_system in (0, self.node.sysid) and msg.target_component in (0, compid)

    def handle_LOG_REQUEST_LIST(self, inc: Incoming) -> None:
        if not self._for_us(inc.msg) or (served := self._transfer(inc)) is None:
            return
        self.counters_.lists += 1
        served.transfer.request_list(self.store.entries(), inc.msg.start, inc.msg.end)
        self.node.wake(inc.channel)

    def handle_LOG_REQUEST_DATA(self, inc: Incoming) -> None:
        if not self._for_us(inc.msg) or (served := self._transfer(inc)) is None:
            return
        m = inc.msg
        served.transfer.request_data(self.store.entries(), m.id, m.ofs, m.count)
        self.node.wake(inc.channel)

    def handle_LOG_REQUEST_END(self, inc: Incoming) -> None:
        served = self._served.get((inc.channel.index, *inc.sender))
        if served is not None and self._for_us(inc.msg):
            served.transfer.end()

    def handle_LOG_ERASE(self, inc: Incoming) -> None:
        if not self._for_us(inc.msg) or self._transfer(inc) is None:
            return
        for served in self._served.values():
            served.transfer.end()
        self.counters_.erased += self.store.erase()

    def pending(self, channel, now: float, send) -> float | None:
        deadline = self.tick(now)
        for served in self._served.values():
            if served.channel_index != channel.index or not served.transfer.busy:
                continue
            due = self._pump(served, channel, now, send)
            if due is not None:
                deadline = due if deadline is None else min(deadline, due)
        return deadline

    def _pump(self, served: _Served, channel, now: float, send) -> float | None:
        t = served.transfer
        bandwidth = channel.config.bandwidth
        for _ in range(PACKETS_PER_PASS):
            item = t.next()
            if item is None:
                return None
            if bandwidth and served.next_send_s > now:
                return served.next_send_s
            if not channel.has_room(MAX_FRAME_BYTES):
                return now + max(channel.budget_wait_s(MAX_FRAME_BYTES), 0.001)
            if isinstance(item, EntryMsg):
                if not send(M.MAVLink_log_entry_message(item.id, item.num_logs, item.last_log_num,
                                                        item.time_utc, item.size)):
                    return now + 0.001
                t.taken()
            else:
                data = self._read(served, item)
                if not send(LogData(item.id, item.ofs, len(data), data)):
                    return now + 0.001
                t.sent(len(data))
                self.counters_.bytes_served += len(data)
            if bandwidth:
                served.next_send_s = max(served.next_send_s, now) + BANDWIDTH_SHARE * LOG_DATA_FRAME_BYTES / bandwidth
        return now if t.busy else None

    def _read(self, served: _Served, chunk: Chunk) -> bytes:
        name, base, data = served.window
        if name != chunk.name or not base <= chunk.ofs or chunk.ofs + chunk.count > base + len(data):
            data = self.store.read(chunk.name, chunk.ofs, READ_MAX)
            base = chunk.ofs
            served.window = (chunk.name, base, data) if len(data) == READ_MAX else ("", 0, b"")
        start = chunk.ofs - base
        return data[start:start + chunk.count]

    # --- the simulated log -----------------------------------------------------------------
    def tick(self, now: float) -> float | None:
        deadline = None
        if self.recorder is not None:
            deadline = self._record(now)
        if self.capture is not None:
            self._apply(self.capture.tick(now), now)
            due = self.capture.next_deadline(now)
            if due is not None:
                deadline = due if deadline is None else min(deadline, due)
        return deadline

    def _record(self, now: float) -> float | None:
        node, state = self.node, self.node.state
        if state.armed:
            self._disarmed_s = None
            if self._sim_file is None:
                self._start_sim_log(now)
        elif self._sim_file is not None and self._disarmed_s is None:
            self._disarmed_s = now
            self._append(self.recorder.text(node.time_usec(now), "Disarming motors"))
        if self._sim_file is None:
            return None
        self._append(self.recorder.sample(now, node.time_usec(now), node.clock.wall(), state))
        if self._disarmed_s is not None and now - self._disarmed_s >= DISARMED_TAIL_S:
            finish_off_loop(self._sim_file)
            self._sim_file, self._disarmed_s = None, None
            return None
        return self.recorder.next_sample_s

    def _start_sim_log(self, now: float) -> None:
        node = self.node
        try:
            self._sim_file = self.store.create(node.clock.wall())
        except OSError as exc:
            log.error("flight_log_create_failed", error=str(exc))
            return
        params = [(e.name, float(e.value), float(e.default)) for e in node.params.entries()]
        banner = node.vehicle.banner(node.params.get)
        head = self.recorder.start(now, node.time_usec(now), node.clock.wall(), node.state, params, banner)
        self._append(head + self.recorder.text(node.time_usec(now), "Arming motors"))

    def _append(self, data: bytes) -> None:
        f = self._sim_file
        if not data or f is None:
            return
        if not f.room_ok():
            self.counters_.write_refused += 1
            return
        try:
            f.append(data)
        except OSError as exc:
            self.counters_.write_refused += 1
            log.error("flight_log_write_failed", file=f.name, error=str(exc))

    # --- capture ---------------------------------------------------------------------------
    def _tap(self, channel, frame, now: float) -> None:
        """Every accepted frame (compose's taps; only a capturing service has one): the flight
        controllers' HEARTBEAT and SYSTEM_TIME, whoever they are addressed to."""
        msgid = frame.msgid
        if msgid != M.MAVLINK_MSG_ID_HEARTBEAT and msgid != M.MAVLINK_MSG_ID_SYSTEM_TIME:
            return
        capture, msg = self.capture, frame.msg
        if msg is None:
            return
        if msgid == M.MAVLINK_MSG_ID_HEARTBEAT:
            self._capture_channels[channel.index] = channel
            effects = capture.handle_heartbeat(channel.index, frame.sysid, frame.compid, msg.autopilot, now)
        else:
            effects = capture.handle_system_time(frame.sysid, msg.time_boot_ms, now)
        self._apply(effects, now)

    def handle_REMOTE_LOG_DATA_BLOCK(self, inc: Incoming) -> None:
        if self.capture is None:
            return
        m = inc.msg
        self._capture_channels[inc.channel.index] = inc.channel
        effects = self.capture.handle_block(inc.channel.index, inc.frame.sysid, inc.frame.compid,
                                            (m.target_system, m.target_component), m.seqno, m.data, inc.now)
        self._apply(effects, inc.now)

    def _apply(self, effects, now: float) -> None:
        node = self.node
        for e in effects:
            if isinstance(e, Status):
                channel = self._capture_channels.get(e.channel)
                if channel is not None:
                    node.reply(channel, M.MAVLink_remote_log_block_status_message(e.sysid, e.compid, e.seqno, e.status))
            elif isinstance(e, Write):
                self._write(e)
            elif isinstance(e, Open):
                self._open(e, node.clock.wall())
            elif isinstance(e, Close):
                f = self._captured.pop(e.key, None)
                if f is not None:
                    finish_off_loop(f)

    def _open(self, e: Open, wall_s: float) -> None:
        try:
            f = self.store.create(wall_s)
        except OSError as exc:
            log.error("flight_log_create_failed", error=str(exc))
            return
        self._captured[e.key] = f
        self._captured_names[e.key] = (f.name, wall_s)
        if len(self._captured_names) > 64:
            del self._captured_names[min(self._captured_names)]

    def _write(self, e: Write) -> None:
        f = self._captured.get(e.key)
        if f is None:  # finished after a silence, and the stream goes on: the same file again
            known = self._captured_names.get(e.key)
            f = self.store.reopen(*known) if known is not None else None
            if f is None:
                self.counters_.write_refused += 1
                return
            self._captured[e.key] = f
        try:
            if not f.room_ok():
                self.counters_.write_refused += 1
                return
            f.write_at(e.offset, e.data)
        except OSError as exc:
            self.counters_.write_refused += 1
            log.error("flight_log_write_failed", file=f.name, error=str(exc))

    # --- shutdown and status ---------------------------------------------------------------
    def shutdown(self, now: float) -> None:
        for f in [*self._captured.values(), *([self._sim_file] if self._sim_file else [])]:
            try:
                f.finish()
            except OSError as exc:
                log.error("flight_log_close_failed", file=f.name, error=str(exc))
        self._captured.clear()
        self._sim_file = None

    def counters(self) -> dict[str, int]:
        out = {f"logs_{k}": v for k, v in vars(self.counters_).items()}
        if self.capture is not None:
            out.update({f"logs_capture_{k}": v for k, v in vars(self.capture.stats).items()})
        return out
