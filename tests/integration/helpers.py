"""Helpers for integration tests: MAVLink nodes on loopback sockets that record what they hear.

A `Client` is a pymavlink connection (`mavutil.mavlink_connection`) whose MAVLink object is pinned
to one dialect and version: MAVLink2 (`pymavlink.dialects.v20`) by default, MAVLink1
(`pymavlink.dialects.v10`) on request. mavutil's automatic version switch (which also sets
MAVLINK20 in the process environment) is turned off, so one client never changes another.

Every read is non-blocking; `pump(clients, seconds)` reads all clients for a while, and each
client keeps what it received as `Received(t, msg, raw)` records (`t` is `time.monotonic()` at
arrival, `raw` the exact bytes of the frame). `client.mark()` / `client.since(mark)` select what
arrived after a point in the test.
"""

from __future__ import annotations

import os
import select
import socket
import subprocess
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from pymavlink import mavutil
from pymavlink.dialects.v10 import ardupilotmega as mavlink1
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

M = mavlink2
VEHICLE = (1, 1)  # the simulated copter's (sysid, compid) in the default configuration


@dataclass(frozen=True)
class Received:
    t: float
    msg: object
    raw: bytes

    @property
    def src(self) -> tuple[int, int]:
        return self.msg.get_srcSystem(), self.msg.get_srcComponent()

    @property
    def type(self) -> str:
        return self.msg.get_type()


RCVBUF_BYTES = 4 << 20


def big_receive_buffer(sock: socket.socket) -> None:
    """The suite runs 4 tests at a time (pytest-xdist): a client descheduled for a moment must not
    lose what the daemon sent meanwhile (a 1 000-parameter list arrives at 3 000 datagrams/s,
    more than the default buffer holds). SO_RCVBUFFORCE (root, as in CI) passes rmem_max."""
    for option in (getattr(socket, "SO_RCVBUFFORCE", None), socket.SO_RCVBUF):
        if option is None:
            continue
        try:
            sock.setsockopt(socket.SOL_SOCKET, option, RCVBUF_BYTES)
            return
        except OSError:
            continue


class Client:
    """One MAVLink node (sysid, compid) on one socket, recording every frame it receives."""

    def __init__(self, url: str, sysid: int, compid: int, version: int = 2) -> None:
        self.conn = mavutil.mavlink_connection(url, source_system=sysid, source_component=compid)
        if self.conn.port.type == socket.SOCK_DGRAM:
            big_receive_buffer(self.conn.port)
        dialect = mavlink2 if version == 2 else mavlink1
        self.mav = dialect.MAVLink(self.conn, srcSystem=sysid, srcComponent=compid)
        self.mav.robust_parsing = True
        self.conn.mav = self.mav
        self.conn.first_byte = False  # no automatic version switch
        self.sysid, self.compid, self.version = sysid, compid, version
        self.received: list[Received] = []
        self.bad_data = 0
        self.bytes_in = 0
        self.chunks: list[bytes] = []  # every datagram / stream read, as received

    # --- sending ---------------------------------------------------------------------------
    def send(self, msg) -> bytes:
        """Send a message from this node; returns the exact bytes that went out."""
        if self.version == 1 and not isinstance(msg, mavlink1.MAVLink_message):
            v1_class = getattr(mavlink1, type(msg).__name__)  # the same message from the v1 dialect
            msg = v1_class(*(getattr(msg, name) for name in v1_class.fieldnames))
        raw = bytes(msg.pack(self.mav))
        self.mav.seq = (self.mav.seq + 1) % 256
        self.write(raw)
        return raw

    def write(self, data: bytes) -> None:
        """Write raw bytes; on a stream socket every byte goes out, in one piece if it fits."""
        sock = self.conn.port
        if sock.type == socket.SOCK_STREAM:
            sock.settimeout(2.0)
            try:
                sock.sendall(data)
            finally:
                sock.setblocking(False)
        else:
            self.conn.write(data)

    def heartbeat(self, mav_type: int = M.MAV_TYPE_GCS) -> bytes:
        return self.send(M.MAVLink_heartbeat_message(mav_type, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))

    def command_long(self, command: int, *params: float, target=VEHICLE, confirmation: int = 0) -> bytes:
        p = list(params) + [0.0] * (7 - len(params))
        return self.send(M.MAVLink_command_long_message(target[0], target[1], command, confirmation, *p))

    def command_int(self, command: int, p1=0.0, p2=0.0, p3=0.0, p4=0.0, x=0, y=0, z=0.0,
                    frame: int = M.MAV_FRAME_GLOBAL, target=VEHICLE) -> bytes:
        return self.send(M.MAVLink_command_int_message(target[0], target[1], frame, command, 0, 0,
                                                       p1, p2, p3, p4, x, y, z))

    # --- receiving -------------------------------------------------------------------------
    def fileno(self) -> int:
        return self.conn.port.fileno()

    def _read_raw(self) -> bytes:
        try:
            return self.conn.port.recv(65536)
        except (BlockingIOError, InterruptedError):
            return b""
        except ConnectionRefusedError:  # ICMP port unreachable on a UDP socket
            return b""

    def read_available(self) -> int:
        """Read and parse everything waiting on the socket now; returns frames added."""
        added = 0
        while True:
            data = self._read_raw()
            if not data:
                return added
            now = time.monotonic()
            self.bytes_in += len(data)
            self.chunks.append(data)
            for msg in self.mav.parse_buffer(data) or []:
                if msg.get_type() == "BAD_DATA":
                    self.bad_data += 1
                    continue
                self.received.append(Received(now, msg, bytes(msg.get_msgbuf())))
                added += 1

    def mark(self) -> int:
        return len(self.received)

    def since(self, mark: int = 0, type: str | None = None) -> list[Received]:
        got = self.received[mark:]
        return [r for r in got if type is None or r.type == type]

    def clear(self) -> None:
        self.received.clear()
        self.chunks.clear()

    def close(self) -> None:
        self.conn.close()


def pump(clients: Iterable[Client], seconds: float) -> None:
    """Read every client for `seconds`."""
    clients = list(clients)
    deadline = time.monotonic() + seconds
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            break
        ready, _, _ = select.select(clients, [], [], min(left, 0.05))
        for c in ready:
            c.read_available()
    for c in clients:
        c.read_available()


def pump_until(clients: Iterable[Client], done: Callable[[], bool], at_least_s: float = 0.0,
               timeout_s: float = 10.0) -> bool:
    """Read every client for `at_least_s` (the window a "nothing arrived" check needs), then on
    until `done()` holds or `timeout_s` (from the start) has passed; returns `done()`. A positive
    control that a loaded machine delays is awaited instead of being expected within the window."""
    clients = list(clients)
    start = time.monotonic()
    pump(clients, at_least_s)
    while not done():
        left = start + timeout_s - time.monotonic()
        if left <= 0:
            return done()
        pump(clients, min(left, 0.05))
    return True


def wait_for(client: Client, match: Callable[[Received], bool], timeout: float = 3.0,
             since: int = 0, others: Iterable[Client] = ()) -> Received | None:
    """Read (also `others`) until `client` has received a frame matching `match` after mark `since`."""
    others = [c for c in others if c is not client]
    deadline = time.monotonic() + timeout
    checked = since
    while True:
        for r in client.received[checked:]:
            if match(r):
                return r
        checked = max(checked, len(client.received))
        left = deadline - time.monotonic()
        if left <= 0:
            return None
        ready, _, _ = select.select([client, *others], [], [], min(left, 0.05))
        for c in ready:
            c.read_available()


def is_type(name: str, src: tuple[int, int] | None = None) -> Callable[[Received], bool]:
    return lambda r: r.type == name and (src is None or r.src == src)


def from_vehicle(r: Received) -> bool:
    return r.src == VEHICLE


def is_ack(command: int) -> Callable[[Received], bool]:
    return lambda r: r.type == "COMMAND_ACK" and r.msg.command == command and r.src == VEHICLE


def rate_hz(records: list[Received]) -> float:
    """Measured rate: intervals between the first and the last arrival, not a raw count."""
    if len(records) < 2:
        return 0.0
    return (len(records) - 1) / (records[-1].t - records[0].t)


def stamped_rate_hz(records: list[Received]) -> float:
    """Measured rate on the sender's clock: intervals between the first and the last `time_boot_ms`
    stamp. A reader descheduled for a moment reads a few frames late and at once, which moves
    arrival times (rate_hz) but not the stamps the daemon wrote when it sent them."""
    if len(records) < 2:
        return 0.0
    return (len(records) - 1) / ((records[-1].msg.time_boot_ms - records[0].msg.time_boot_ms) / 1000)


def measure_rates(clients: dict[str, Client], kinds: dict[str, tuple[str, ...]], seconds: float,
                  src: tuple[int, int] = VEHICLE) -> dict[tuple[str, str], float]:
    """Rates (Hz) of each message type in kinds[name] as received by clients[name] over `seconds`."""
    marks = {name: c.mark() for name, c in clients.items()}
    pump(clients.values(), seconds)
    out = {}
    for name, c in clients.items():
        for kind in kinds.get(name, ()):
            out[(name, kind)] = rate_hz([r for r in c.since(marks[name], kind) if r.src == src])
    return out


def v2_frame(msgid: int, payload: bytes, sysid: int = 255, compid: int = 190, seq: int = 0,
             crc: bytes = b"\x12\x34") -> bytes:
    """A hand-built MAVLink2 frame (unsigned) with any message id and any CRC bytes."""
    header = bytes([0xFD, len(payload), 0, 0, seq & 0xFF, sysid, compid,
                    msgid & 0xFF, (msgid >> 8) & 0xFF, (msgid >> 16) & 0xFF])
    return header + payload + crc


def packed(msg, sysid: int = 255, compid: int = 190, version: int = 2) -> bytes:
    """The bytes of one message from (sysid, compid), packed without a connection."""
    mav = (mavlink2 if version == 2 else mavlink1).MAVLink(None, srcSystem=sysid, srcComponent=compid)
    return bytes(msg.pack(mav))


def udp_url(port: int) -> str:
    return f"udpout:127.0.0.1:{port}"


def tcp_url(port: int) -> str:
    return f"tcp:127.0.0.1:{port}"


def udp_channel(name: str, **extra) -> dict:
    return {"name": name, "type": "udp-server", "address": "127.0.0.1:0", **extra}


def tcp_channel(name: str, **extra) -> dict:
    return {"name": name, "type": "tcp-server", "address": "127.0.0.1:0", **extra}


def free_listener(kind: int = socket.SOCK_STREAM) -> socket.socket:
    """A test-owned socket bound to an ephemeral loopback port (listening, for TCP)."""
    sock = socket.socket(socket.AF_INET, kind)
    sock.bind(("127.0.0.1", 0))
    if kind == socket.SOCK_STREAM:
        sock.listen(4)
    return sock


def read_fd(fd: int, seconds: float, sink: bytearray) -> None:
    """Read a non-blocking file descriptor for `seconds`, appending to sink."""
    deadline = time.monotonic() + seconds
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return
        ready, _, _ = select.select([fd], [], [], min(left, 0.05))
        if ready:
            try:
                sink += os.read(fd, 65536)
            except (BlockingIOError, InterruptedError):
                pass


def download_params(c: Client, timeout: float = 10.0, others: Iterable[Client] = (),
                    target: tuple[int, int] = VEHICLE) -> dict[int, tuple[str, float, int]]:
    """A full parameter list as MAVProxy downloads it: PARAM_REQUEST_LIST, then PARAM_REQUEST_READ
    of up to 10 missing indices after each second without a new value. index -> (name, value, type)."""
    mark = c.mark()
    c.send(M.MAVLink_param_request_list_message(*target))
    got: dict[int, tuple[str, float, int]] = {}
    count = None
    deadline = time.monotonic() + timeout
    last_new = time.monotonic()
    seen = mark
    while time.monotonic() < deadline:
        pump([c, *others], 0.05)
        for r in c.received[seen:]:
            if r.type == "PARAM_VALUE" and r.src == target and r.msg.param_index != 65535:
                count = r.msg.param_count
                if r.msg.param_index not in got:
                    got[r.msg.param_index] = (r.msg.param_id, r.msg.param_value, r.msg.param_type)
                    last_new = time.monotonic()
        seen = len(c.received)
        if count is not None and len(got) == count:
            return got
        if count is not None and time.monotonic() - last_new > 1.0:
            for i in [i for i in range(count) if i not in got][:10]:
                c.send(M.MAVLink_param_request_read_message(*target, b"", i))
            last_new = time.monotonic()
    raise AssertionError(f"parameter download incomplete: {len(got)} of {count}")


START_TIMEOUT_S = 30.0  # a gcsd process's start, awaited: 0.5 s alone, seconds beside 4 test workers on 2 cores


def notify_socket(directory: Path, timeout_s: float = START_TIMEOUT_S) -> tuple[socket.socket, Path]:
    """The socket systemd would read: a daemon started with NOTIFY_SOCKET=its path writes to it."""
    path = directory / "notify.sock"
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    sock.bind(str(path))
    sock.settimeout(timeout_s)
    return sock, path


def await_ready(notify: socket.socket, proc: subprocess.Popen, timeout_s: float = START_TIMEOUT_S) -> str:
    """The daemon's READY=1 on its notify socket (every server channel bound, every client channel
    tried: what systemd waits for), awaited with a generous deadline; fails at once if the
    process exits first. The control socket is no such sign: it exists before the channels."""
    deadline = time.monotonic() + timeout_s
    timeout = notify.gettimeout()
    notify.settimeout(0.1)
    try:
        while True:
            try:
                text = notify.recv(4096).decode()
            except TimeoutError:
                assert proc.poll() is None, f"gcsd exited at start with {proc.returncode}"
                assert time.monotonic() < deadline, f"no READY=1 within {timeout_s} s"
                continue
            if text.startswith("READY=1"):
                return text
    finally:
        notify.settimeout(timeout)
