"""Capture of DataFlash logs streamed over MAVLink (ArduPilot's AP_Logger_MAVLink, REFERENCE.md 15).

Pure: `handle_*` and `tick` take `now` and return effects; the service sends and writes them.
Effects: `Status` (a REMOTE_LOG_BLOCK_STATUS to send), `Open(key, sysid)` (a new `.BIN` for
that flight controller), `Write(key, offset, data)`, `Close(key)` (finished: fsync, close).

One `Session` per flight controller (sysid; at most MAX_SOURCES), created by its HEARTBEAT
(an ArduPilot autopilot on a capture channel) or its first block. States:

- WAITING (no file): START (`REMOTE_LOG_BLOCK_STATUS` seqno MAV_REMOTE_LOG_DATA_BLOCK_START,
  status 1, to the autopilot component) now and every START_INTERVAL_S. A block with seqno 0
  opens a file. A block with another seqno is an orphan stream (a flight controller still
  streaming to our previous run: START is ignored while it streams), answered with STOP then
  START (at most every START_INTERVAL_S), which begins a new log at seqno 0. A block below
  WINDOW after our START is that new log whose block 0 was lost: it opens the file.
- STREAMING (file open): every block is written at seqno x 200 (whole 200-byte blocks; the
  trailing zeros MAVLink2 trims are restored) and ACKed at once (a duplicate too: our ACK was
  lost). Seqnos skipped over become missing; each missing block is NACKed every NACK_INTERVAL_S
  until it arrives (ArduPilot also re-sends unacknowledged blocks every 100 ms by itself), and
  abandoned after ABANDON_S. A block more than MAX_AHEAD past the highest is ignored (counted).
  After START_AFTER_SILENCE_S without a block, START again every START_INTERVAL_S: ignored by a
  flight controller that is only pausing (it continues at the next seqno, same file), obeyed by
  one that stopped (10 s without our answers) or rebooted, which begins at seqno 0 again.
  STOP is never sent on a gap (mavlink-router's "binlog storm").
- A new sequence: a block we are not missing and more than RESTART_SPAN below the highest
  (a duplicate from that far back would need our ACK lost six times running), a block below
  WINDOW that we already hold after we asked for a START since the last block, or a block 0
  whose bytes differ from the file's: Close the file, Open a new one. A missing block is never
  a new sequence, however far back: ArduPilot holds it until it is ACKed.
- CLOSED after CLOSE_AFTER_S without a block: the file is Closed; a stream that resumes with the
  next seqno is written to the same file again (the service reopens it).
- A reboot (HEARTBEAT back after HEARTBEAT_LOST_S, or SYSTEM_TIME's time_boot_ms going back):
  START at once; the flight controller streams again only after one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

BLOCK_BYTES = 200
SEQ_START = 2147483646  # MAV_REMOTE_LOG_DATA_BLOCK_START
SEQ_STOP = 2147483645  # MAV_REMOTE_LOG_DATA_BLOCK_STOP
ACK, NACK = 1, 0
MAV_AUTOPILOT_ARDUPILOTMEGA = 3

START_INTERVAL_S = 1.0
START_AFTER_SILENCE_S = 1.0
CLOSE_AFTER_S = 5.0
NACK_INTERVAL_S = 0.1
ABANDON_S = 60.0
HEARTBEAT_LOST_S = 3.0
WINDOW = 64  # a new log's first blocks: below this after our START
RESTART_SPAN = 256  # an old block this far below the highest that we are not missing: a new log
MAX_AHEAD = 1024
MAX_MISSING = 2048
MAX_NACKS_PER_TICK = 64
MAX_SOURCES = 4


@dataclass(frozen=True, slots=True)
class Status:
    channel: int
    sysid: int
    compid: int
    seqno: int
    status: int


@dataclass(frozen=True, slots=True)
class Open:
    key: int
    sysid: int


@dataclass(frozen=True, slots=True)
class Write:
    key: int
    offset: int
    data: bytes


@dataclass(frozen=True, slots=True)
class Close:
    key: int


@dataclass
class CaptureStats:
    blocks: int = 0
    duplicates: int = 0
    recovered: int = 0  # missing blocks that arrived later
    abandoned: int = 0
    ignored: int = 0  # not for us, too far ahead, unknown source beyond MAX_SOURCES
    logs: int = 0
    starts_sent: int = 0
    nacks_sent: int = 0


@dataclass
class Session:
    sysid: int
    channel: int
    autopilot_compid: int = 1
    log_compid: int = 155  # MAV_COMP_ID_LOG: where ArduPilot's blocks come from
    key: int | None = None  # the open log's key; None: WAITING
    closed: bool = False  # the log was Closed after a silence (it may continue)
    highest: int = -1
    block0: bytes | None = None
    missing: dict[int, list[float]] = field(default_factory=dict)  # seqno -> [first_s, last_nack_s]
    last_block_s: float | None = None
    last_start_s: float | None = None
    last_stop_s: float | None = None
    started_since_block: bool = True  # we asked for a START since the last block
    last_heartbeat_s: float | None = None
    boot_ms: int | None = None


class Capture:
    def __init__(self, sysid: int, compid: int, channels: frozenset[int] | None = None) -> None:
        self.sysid, self.compid = sysid, compid
        self.channels = channels  # None: every channel
        self.sessions: dict[int, Session] = {}
        self.stats = CaptureStats()
        self._next_key = 1

    # --- inputs ----------------------------------------------------------------------------
    def handle_heartbeat(self, channel: int, sysid: int, compid: int, autopilot: int, now: float) -> list:
        if autopilot != MAV_AUTOPILOT_ARDUPILOTMEGA or (sysid, compid) == (self.sysid, self.compid) \
                or not self._listens(channel):
            return []
        s = self._session(sysid, channel)
        if s is None:
            return []
        out = []
        lost = s.last_heartbeat_s is not None and now - s.last_heartbeat_s > HEARTBEAT_LOST_S
        s.channel, s.autopilot_compid, s.last_heartbeat_s = channel, compid, now
        if lost or s.last_start_s is None:
            out += self._start(s, now)
        return out

    def handle_system_time(self, sysid: int, time_boot_ms: int, now: float) -> list:
        s = self.sessions.get(sysid)
        if s is None:
            return []
        rebooted = s.boot_ms is not None and time_boot_ms + 1000 < s.boot_ms
        s.boot_ms = time_boot_ms
        return self._start(s, now) if rebooted else []

    def handle_block(self, channel: int, sysid: int, compid: int, target: tuple[int, int], seqno: int,
                     data, now: float) -> list:
        if target != (self.sysid, self.compid) or not self._listens(channel) or seqno >= SEQ_STOP:
            self.stats.ignored += 1
            return []
        s = self._session(sysid, channel)
        if s is None:
            self.stats.ignored += 1
            return []
        block = bytes(data[:BLOCK_BYTES]).ljust(BLOCK_BYTES, b"\0")
        out: list = []
        if s.key is not None and self._new_sequence(s, seqno, block):
            out += [Close(s.key), *self._open(s)]  # its first blocks may be missing: NACKed below
        elif s.key is None:
            if seqno != 0 and not (seqno < WINDOW and s.started_since_block):
                return out + self._orphan(s, channel, sysid, compid, now)
            out += self._open(s)
        elif seqno > s.highest + MAX_AHEAD:
            self.stats.ignored += 1
            return out
        s.last_block_s = now
        s.channel, s.log_compid = channel, compid
        s.started_since_block = False
        s.closed = False
        ack = Status(channel, sysid, compid, seqno, ACK)
        if seqno <= s.highest and seqno not in s.missing:
            self.stats.duplicates += 1
            return out + [ack]
        self.stats.blocks += 1
        if seqno in s.missing:
            del s.missing[seqno]
            self.stats.recovered += 1
        elif seqno > s.highest:
            for gap in range(max(s.highest + 1, seqno - MAX_MISSING), seqno):
                s.missing[gap] = [now, now - NACK_INTERVAL_S]
            s.highest = seqno
            self._bound_missing(s)
        if seqno == 0:
            s.block0 = block
        out.append(Write(s.key, seqno * BLOCK_BYTES, block))
        out.append(ack)
        return out

    # --- time ------------------------------------------------------------------------------
    def tick(self, now: float) -> list:
        out: list = []
        for s in self.sessions.values():
            quiet_s = now - s.last_block_s if s.last_block_s is not None else None
            silent = s.key is None or quiet_s is None or quiet_s >= START_AFTER_SILENCE_S
            if silent and (s.last_start_s is None or now - s.last_start_s >= START_INTERVAL_S):
                out += self._start(s, now)
            if s.key is not None and not s.closed and quiet_s is not None and quiet_s >= CLOSE_AFTER_S:
                s.closed = True
                out.append(Close(s.key))
            out += self._nacks(s, now)
        return out

    def next_deadline(self, now: float) -> float | None:
        deadline = None
        for s in self.sessions.values():
            times = []
            if s.last_start_s is not None:
                start_due = s.last_start_s + START_INTERVAL_S
                if s.key is not None and s.last_block_s is not None:
                    start_due = max(start_due, s.last_block_s + START_AFTER_SILENCE_S)
                times.append(start_due)
            if s.key is not None and not s.closed and s.last_block_s is not None:
                times.append(s.last_block_s + CLOSE_AFTER_S)
            if s.missing:
                times.append(min(v[1] for v in s.missing.values()) + NACK_INTERVAL_S)
            for t in times:
                deadline = t if deadline is None else min(deadline, t)
        return None if deadline is None else max(deadline, now)

    # --- internals -------------------------------------------------------------------------
    def _listens(self, channel: int) -> bool:
        return self.channels is None or channel in self.channels

    def _session(self, sysid: int, channel: int) -> Session | None:
        s = self.sessions.get(sysid)
        if s is None:
            if len(self.sessions) >= MAX_SOURCES:
                return None
            s = self.sessions[sysid] = Session(sysid, channel)
        return s

    def _new_sequence(self, s: Session, seqno: int, block: bytes) -> bool:
        if seqno in s.missing:
            return False  # a block we are waiting for (ArduPilot re-sends it until it is ACKed)
        if seqno + RESTART_SPAN < s.highest:
            return True
        if seqno < WINDOW and seqno <= s.highest and s.started_since_block:
            return True
        return seqno == 0 and s.block0 is not None and block != s.block0

    def _open(self, s: Session) -> list:
        s.key, self._next_key = self._next_key, self._next_key + 1
        s.highest, s.block0, s.missing, s.closed = -1, None, {}, False
        self.stats.logs += 1
        return [Open(s.key, s.sysid)]

    def _start(self, s: Session, now: float) -> list:
        s.last_start_s = now
        s.started_since_block = True
        self.stats.starts_sent += 1
        return [Status(s.channel, s.sysid, s.autopilot_compid, SEQ_START, 1)]

    def _orphan(self, s: Session, channel: int, sysid: int, compid: int, now: float) -> list:
        self.stats.ignored += 1
        if s.last_stop_s is not None and now - s.last_stop_s < START_INTERVAL_S:
            return []
        s.last_stop_s = now
        return [Status(channel, sysid, compid, SEQ_STOP, 1), *self._start(s, now)]

    def _bound_missing(self, s: Session) -> None:
        while len(s.missing) > MAX_MISSING:
            del s.missing[min(s.missing)]
            self.stats.abandoned += 1

    def _nacks(self, s: Session, now: float) -> list:
        out = []
        for seqno, times in list(s.missing.items()):
            if now - times[0] >= ABANDON_S:
                del s.missing[seqno]
                self.stats.abandoned += 1
            elif now - times[1] >= NACK_INTERVAL_S and len(out) < MAX_NACKS_PER_TICK:
                times[1] = now
                out.append(Status(s.channel, s.sysid, s.log_compid, seqno, NACK))
        self.stats.nacks_sent += len(out)
        return out

