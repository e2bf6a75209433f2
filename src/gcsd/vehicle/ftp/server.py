"""The MAVLink FTP server core: requests in, reply payloads out, time passed in as `now`.

`handle(raw, sender, channel, now)` takes one FILE_TRANSFER_PROTOCOL payload and returns the
replies to send now; `pump(channel, now, max_packets)` returns the burst packets due by `now`
and finished CRC computations (at most `max_packets`, so the adapter can also hold them to the
link's byte budget); `next_deadline(now)` says when either is next needed. No sockets, no clock, no
asyncio here; file access goes through the injected ConfinedFs and VirtualFiles, whose every
call is bounded (see fs.py).

**Sessions.** A session is keyed by (sysid, compid, channel, session byte): the client picks
the session number and every reply echoes it, so several ground stations, and several
operations of one ground station (MAVProxy runs up to 5), never share state. At most
MAX_SESSIONS (5) exist. A new key takes a free slot, else the slot of the least recently used
session that has no open file, no burst and no CRC running and has been idle for
SESSION_REUSE_S (3 s); else the request gets NAK NoSessionsAvailable. A session idle for
SESSION_IDLE_S (30 s) is closed: its file closed, an unfinished virtual upload dropped.
TerminateSession closes the session's file and frees the session (ACK; a NAK when closing
failed, e.g. a malformed param.pck upload); for an unknown session it is a plain ACK.
ResetSessions closes every session of the requesting (sysid, compid) and ACKs.

**Retries.** Each session keeps its last request and the replies sent for it. A request
byte-identical to the last one (a client's retransmission: same seq, opcode and data) gets the
stored replies again without being executed twice. A repeat of a running burst or CRC is
ignored; a repeat of a finished burst runs it again from the requested offset. Reply seq =
request seq + 1, wrapping at 65536; burst packets count on from there.

**Opcodes** (REFERENCE.md section 8; the spec's meaning where ArduPilot differs):
None -> ACK. ACK/NAK from a client -> ignored. Request size > 239 -> InvalidDataSize; a path
whose size is not its length (or length + 1) -> InvalidDataSize. One file per session:
OpenFileRO/CreateFile/OpenFileWO with a file open -> Fail (a file idle for 3 s is closed
first). OpenFileRO -> ACK with the exact u32 size. ReadFile -> ACK with up to min(size, 239)
bytes at offset, EOF past the end, FileNotFound without a file, Fail on a file open for
writing. CreateFile truncates, OpenFileWO does not; both create. WriteFile -> ACK, offset
echoed (a write past `ftp.max_file_bytes` -> FailErrno EFBIG). RemoveFile removes a file
(a directory -> FailErrno EISDIR), RemoveDirectory an empty directory. TruncateFile sets the
length to `offset`. Rename "old\\0new". CalcFileCRC32 -> ACK with ArduPilot's CRC-32 (seed 0,
no final XOR), computed CRC_SLICE_BYTES per pump for big files. ListDirectory -> entries
"F<name>\\t<size>\\0" and "D<name>\\0" from index `offset`, sorted by name, "/" also lists the
virtual directories; no entries -> EOF. BurstReadFile -> packets of the requested block size
(239 when 0) from `offset`, paced, burst_complete on the last; NAK EOF after the end. Unknown
opcodes -> UnknownCommand, ListDirectoryWithTime (16, newer than ArduPilot) included: MAVProxy
then lists without times.

Bursts (their length, pace and the repeated burst_complete packet) are in burst.py. A read
in a session whose burst has already passed that offset is a gap request: a loss signal that
slows the session's bursts down.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

from gcsd.vehicle.ftp.burst import Burst, Pace
from gcsd.vehicle.ftp.fs import ConfinedFs, DirEntry
from gcsd.vehicle.ftp.protocol import (
    DATA_MAX,
    FtpError,
    Nak,
    Op,
    Payload,
    crc32_ardupilot,
    path_arg,
    two_path_args,
)
from gcsd.vehicle.ftp.virtual import Handle, VirtualFiles, split_virtual

MAX_SESSIONS = 5
SESSION_IDLE_S = 30.0
SESSION_REUSE_S = 3.0
OPEN_FILE_STALE_S = 3.0
CRC_SLICE_BYTES = 1 << 20
CRC_READ_BYTES = 64 * 1024
CLOSED_REPLIES_KEPT = 16

SessionKey = tuple[int, int, int, int]  # sysid, compid, channel, session byte


@dataclass(frozen=True, slots=True)
class Outgoing:
    channel: int
    target: tuple[int, int]  # (sysid, compid) of the requester
    payload: bytes


@dataclass(slots=True)
class _Crc:
    request: Payload
    raw: bytes
    handle: Handle
    offset: int = 0
    crc: int = 0


@dataclass(slots=True)
class _Session:
    key: SessionKey
    last_s: float
    handle: Handle | None = None
    handle_s: float = 0.0  # when the open file was last used
    last_request: bytes | None = None
    last_replies: list[bytes] | None = None
    burst: Burst | None = None
    crc: _Crc | None = None
    pace: Pace = field(default_factory=Pace)

    @property
    def busy(self) -> bool:
        return self.handle is not None or self.burst is not None or self.crc is not None


class FtpServer:
    def __init__(self, fs: ConfinedFs, virtual: VirtualFiles | None = None) -> None:
        self.fs = fs
        self.virtual = virtual or VirtualFiles()
        self._sessions: dict[SessionKey, _Session] = {}
        self._closed: OrderedDict[SessionKey, tuple[bytes, bytes]] = OrderedDict()
        self._ops: dict[int, Callable[[_Session, Payload, float], list[Payload]]] = {
            Op.NONE: lambda s, req, now: [req.ack()],
            Op.TERMINATE_SESSION: self._terminate,
            Op.LIST_DIRECTORY: self._list_directory,
            Op.OPEN_FILE_RO: self._open_ro,
            Op.READ_FILE: self._read,
            Op.CREATE_FILE: self._open_wo,
            Op.OPEN_FILE_WO: self._open_wo,
            Op.WRITE_FILE: self._write,
            Op.REMOVE_FILE: self._path_op(self.fs.remove_file),
            Op.CREATE_DIRECTORY: self._path_op(self.fs.mkdir),
            Op.REMOVE_DIRECTORY: self._path_op(self.fs.remove_dir),
            Op.TRUNCATE_FILE: self._truncate,
            Op.RENAME: self._rename,
            Op.CALC_FILE_CRC32: self._crc32,
            Op.BURST_READ_FILE: self._burst_read,
        }

    # --- requests --------------------------------------------------------------------------
    def handle(self, raw: bytes, sender: tuple[int, int], channel: int, now: float) -> list[Outgoing]:
        req = Payload.unpack(raw)
        if req.opcode in (Op.ACK, Op.NAK):
            return []
        self.expire(now)
        raw = req.pack()  # normalised: a retransmission compares equal whatever its trimming
        key = (sender[0], sender[1], channel, req.session)

        def out(replies: list[bytes]) -> list[Outgoing]:
            return [Outgoing(channel, sender, p) for p in replies]

        if req.opcode == Op.RESET_SESSIONS:
            for k in [k for k in self._sessions if k[:2] == sender]:
                self._drop(k)
            return out([req.ack().pack()])
        session = self._sessions.get(key)
        if session is None:
            if req.opcode == Op.TERMINATE_SESSION:
                closed = self._closed.get(key)
                return out([closed[1] if closed and closed[0] == raw else req.ack().pack()])
            session = self._allocate(key, now)
            if session is None:
                return out([req.nak(Nak.NO_SESSIONS_AVAILABLE).pack()])
        session.last_s = now
        if raw == session.last_request:
            if session.last_replies is not None:
                return out(session.last_replies)
            running = session.burst or session.crc
            if running is not None and running.raw == raw:
                return []
        session.last_request, session.last_replies = raw, None
        if session.burst is not None and req.opcode in (Op.READ_FILE, Op.BURST_READ_FILE) \
                and req.offset < session.burst.offset:
            session.pace.loss()  # the client asks again for what the burst has sent: it lost some
        op = self._ops.get(req.opcode)
        try:
            if req.size > DATA_MAX:
                raise FtpError(Nak.INVALID_DATA_SIZE)
            if op is None:
                raise FtpError(Nak.UNKNOWN_COMMAND)
            replies = op(session, req, now)
        except FtpError as exc:
            session.burst = None if req.opcode == Op.BURST_READ_FILE else session.burst
            replies = [req.nak(exc.code, exc.errno_value)]
        packed = [r.pack() for r in replies]
        if req.opcode == Op.TERMINATE_SESSION:
            self._sessions.pop(key, None)
            self._closed[key] = (raw, packed[0])
            while len(self._closed) > CLOSED_REPLIES_KEPT:
                self._closed.popitem(last=False)
        elif packed or (session.burst is None and session.crc is None):
            session.last_replies = packed
        return out(packed)

    def _allocate(self, key: SessionKey, now: float) -> _Session | None:
        if len(self._sessions) >= MAX_SESSIONS:
            idle = [s for s in self._sessions.values() if not s.busy and now - s.last_s >= SESSION_REUSE_S]
            if not idle:
                return None
            del self._sessions[min(idle, key=lambda s: s.last_s).key]
        self._closed.pop(key, None)
        session = self._sessions[key] = _Session(key, now)
        return session

    def _drop(self, key: SessionKey) -> None:
        session = self._sessions.pop(key)
        for handle in (session.handle, session.crc.handle if session.crc else None):
            if handle is not None:
                handle.abort()

    def expire(self, now: float) -> None:
        """Close sessions idle for SESSION_IDLE_S."""
        for key in [k for k, s in self._sessions.items() if now - s.last_s >= SESSION_IDLE_S]:
            self._drop(key)

    def session_count(self) -> int:
        return len(self._sessions)

    # --- opcodes ---------------------------------------------------------------------------
    def _terminate(self, s: _Session, req: Payload, now: float) -> list[Payload]:
        handle, s.handle, s.burst = s.handle, None, None
        if s.crc is not None:
            s.crc.handle.abort()
            s.crc = None
        if handle is not None:
            handle.close()  # an FtpError here is the NAK
        return [req.ack()]

    def _open(self, s: _Session, raw_path: bytes, now: float, writer: bool, truncate: bool = False) -> Handle:
        if s.handle is not None:
            if now - s.handle_s < OPEN_FILE_STALE_S or s.burst is not None:
                raise FtpError(Nak.FAIL)
            s.handle.abort()  # the client lost this file long ago
            s.handle = None
        virtual = split_virtual(raw_path)
        if virtual is None:
            handle = self.fs.open_write(raw_path, truncate) if writer else self.fs.open_read(raw_path)
        elif writer:
            handle = self.virtual.open_write(*virtual)
        else:
            handle = self.virtual.open_read(*virtual)
        s.handle, s.handle_s = handle, now
        return handle

    def _open_ro(self, s: _Session, req: Payload, now: float) -> list[Payload]:
        handle = self._open(s, path_arg(req), now, writer=False)
        return [req.ack(min(handle.size, 0xFFFFFFFF).to_bytes(4, "little"))]

    def _open_wo(self, s: _Session, req: Payload, now: float) -> list[Payload]:
        self._open(s, path_arg(req), now, writer=True, truncate=req.opcode == Op.CREATE_FILE)
        return [req.ack()]

    def _reading(self, s: _Session, now: float) -> Handle:
        if s.handle is None:
            raise FtpError(Nak.FILE_NOT_FOUND)
        if s.handle.writable:
            raise FtpError(Nak.FAIL)
        s.handle_s = now
        return s.handle

    def _read(self, s: _Session, req: Payload, now: float) -> list[Payload]:
        data = self._reading(s, now).read(req.offset, min(req.size, DATA_MAX))
        if not data:
            return [req.nak(Nak.EOF)]
        return [req.ack(data)]

    def _write(self, s: _Session, req: Payload, now: float) -> list[Payload]:
        if s.handle is None:
            raise FtpError(Nak.FILE_NOT_FOUND)
        if not s.handle.writable:
            raise FtpError(Nak.FAIL)
        s.handle_s = now
        s.handle.write(req.offset, req.data[:req.size])
        return [req.ack()]

    def _real_path(self, raw_path: bytes) -> bytes:
        """A path for a filesystem-changing opcode: virtual names are protected, or unknown."""
        virtual = split_virtual(raw_path)
        if virtual is not None:
            raise FtpError(Nak.FILE_PROTECTED if self.virtual.exists(*virtual) else Nak.FILE_NOT_FOUND)
        return raw_path

    def _path_op(self, fn: Callable[[bytes], None]):
        def op(s: _Session, req: Payload, now: float) -> list[Payload]:
            fn(self._real_path(path_arg(req)))
            return [req.ack()]
        return op

    def _truncate(self, s: _Session, req: Payload, now: float) -> list[Payload]:
        self.fs.truncate(self._real_path(path_arg(req)), req.offset)
        return [req.ack()]

    def _rename(self, s: _Session, req: Payload, now: float) -> list[Payload]:
        old, new = two_path_args(req)
        self.fs.rename(self._real_path(old), self._real_path(new))
        return [req.ack()]

    def _list_directory(self, s: _Session, req: Payload, now: float) -> list[Payload]:
        raw_path = path_arg(req)
        if len(raw_path) > 1 and raw_path.endswith(b"/"):
            raw_path = raw_path[:-1]
        virtual = split_virtual(raw_path)
        if virtual is not None:
            entries = self.virtual.list_dir(*virtual)
        else:
            entries = self.fs.list_dir(raw_path)
            if self.fs.resolve(raw_path) == self.fs.root:  # "@..." names at the root are virtual
                entries = [e for e in entries if not e.name.startswith("@")] + self.virtual.root_entries()
        packed = [p for p in map(_dir_entry, entries) if len(p) < DATA_MAX]
        data = bytearray()
        for entry in packed[req.offset:]:
            if len(data) + len(entry) >= DATA_MAX:
                break
            data += entry
        if not data:
            return [req.nak(Nak.EOF)]
        return [req.ack(bytes(data))]

    def _crc32(self, s: _Session, req: Payload, now: float) -> list[Payload]:
        raw_path = path_arg(req)
        virtual = split_virtual(raw_path)
        handle = self.virtual.open_read(*virtual, announce=False) if virtual else self.fs.open_read(raw_path)
        if s.crc is not None:
            s.crc.handle.abort()
        s.crc = _Crc(req, req.pack(), handle)
        return self._crc_step(s)

    def _crc_step(self, s: _Session) -> list[Payload]:
        job = s.crc
        budget = CRC_SLICE_BYTES
        try:
            while budget > 0:
                chunk = job.handle.read(job.offset, CRC_READ_BYTES)
                if not chunk:
                    s.crc = None
                    job.handle.abort()
                    return [job.request.ack(job.crc.to_bytes(4, "little"))]
                job.crc = crc32_ardupilot(chunk, job.crc)
                job.offset += len(chunk)
                budget -= len(chunk)
        except FtpError as exc:
            s.crc = None
            job.handle.abort()
            return [job.request.nak(exc.code, exc.errno_value)]
        return []

    def _burst_read(self, s: _Session, req: Payload, now: float) -> list[Payload]:
        self._reading(s, now)
        s.burst = Burst.start(req, now)
        return []

    # --- bursts and slow work --------------------------------------------------------------
    def pump(self, channel: int, now: float, max_packets: int) -> list[Outgoing]:
        """Packets of running bursts and finished CRCs on one channel, at most max_packets."""
        out: list[Outgoing] = []
        for s in list(self._sessions.values()):
            if s.key[2] != channel:
                continue
            target = s.key[:2]
            if s.crc is not None and len(out) < max_packets:
                job = s.crc
                replies = [r.pack() for r in self._crc_step(s)]
                if replies and s.last_request == job.raw:
                    s.last_replies = replies
                out += [Outgoing(channel, target, p) for p in replies]
            burst = s.burst
            while burst is not None and len(out) < max_packets and burst.due(now):
                out.append(Outgoing(channel, target, burst.next_packet(s.handle, s.pace, now).pack()))
                if burst.done:
                    s.burst = burst = None
            if s.burst is not None or s.crc is not None:
                s.last_s = s.handle_s = now
        return out

    def has_work(self, channel: int) -> bool:
        return any(s.key[2] == channel and (s.burst or s.crc) for s in self._sessions.values())

    def next_deadline(self, now: float, channel: int | None = None) -> float | None:
        """now while a CRC runs, a burst's next packet time, else the next idle expiry (of the
        sessions on `channel`, or of all)."""
        sessions = [s for s in self._sessions.values() if channel is None or s.key[2] == channel]
        times = [now if s.crc else s.burst.next_s for s in sessions if s.crc or s.burst]
        times += [s.last_s + SESSION_IDLE_S for s in sessions]
        return min(times) if times else None


def _dir_entry(e: DirEntry) -> bytes:
    name = e.name.encode("utf-8", "surrogateescape")
    if e.is_dir:
        return b"D" + name + b"\0"
    return b"F" + name + b"\t" + str(e.size).encode() + b"\0"
