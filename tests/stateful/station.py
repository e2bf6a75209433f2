"""Ground stations for the stateful test: a raw socket (UDP or TCP) per station, a sending MAVLink
object that may sign, and a receiving parser without a key (so a reply signed with a key the
station does not hold yet is still read, and unsigned replies are never refused client-side).

`Monitor` is one station in a thread of its own on the daemon's `unsigned_ok` channel: it sends a
HEARTBEAT every second (so it stays a served peer) and records the arrival time of every
HEARTBEAT the vehicle sends, and every STATUSTEXT, for the 1 Hz check.
"""

from __future__ import annotations

import select
import socket
import threading
import time
from collections.abc import Callable

from pymavlink.dialects.v10 import ardupilotmega as mavlink1
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.wire.signing import EPOCH_2015_S, UNITS_PER_S

GCS_HEARTBEAT = M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)


def now_units(offset_s: float = 0.0) -> int:
    """A signing timestamp (10 us units since 2015) from this host's wall clock."""
    return int((time.time() + offset_s - EPOCH_2015_S) * UNITS_PER_S)


class Station:
    """One ground station: `kind` "udp" or "tcp", to 127.0.0.1:port."""

    def __init__(self, kind: str, port: int, sysid: int = 255, compid: int = 190, version: int = 2) -> None:
        self.kind, self.port, self.sysid, self.version = kind, port, sysid, version
        if kind == "tcp":
            self.sock = socket.create_connection(("127.0.0.1", port), timeout=2.0)
        else:
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.connect(("127.0.0.1", port))
        self.sock.setblocking(False)
        dialect = M if version == 2 else mavlink1
        self.tx = dialect.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.rx = M.MAVLink(None)
        self.rx.robust_parsing = True
        self.key: bytes | None = None
        self.closed = False

    def sign(self, key: bytes | None, link_id: int = 0, offset_s: float = 0.0) -> None:
        """Sign from now on with `key` (None: unsigned), a fresh timestamp from the wall clock."""
        self.key = key
        self.tx.signing.secret_key = key
        self.tx.signing.link_id = link_id
        self.tx.signing.timestamp = now_units(offset_s)
        self.tx.signing.sign_outgoing = key is not None

    def pack(self, msg) -> bytes:
        if self.version == 1 and not isinstance(msg, mavlink1.MAVLink_message):
            v1 = getattr(mavlink1, type(msg).__name__)
            values = (getattr(msg, name) for name in v1.fieldnames)
            msg = v1(*(v.encode() if isinstance(v, str) else v for v in values))
        raw = bytes(msg.pack(self.tx))
        self.tx.seq = (self.tx.seq + 1) % 256
        return raw

    def send(self, msg) -> bytes:
        raw = self.pack(msg)
        self.write(raw)
        return raw

    def write(self, data: bytes) -> None:
        if self.closed:
            return
        try:
            if self.kind == "tcp":
                self.sock.settimeout(2.0)
                try:
                    self.sock.sendall(data)
                finally:
                    self.sock.setblocking(False)
            else:
                self.sock.send(data)
        except (ConnectionRefusedError, BlockingIOError):
            pass  # UDP: ICMP from a port that is gone (a restart), or a full buffer
        except OSError:
            self.closed = True  # TCP: the daemon closed or reset this connection

    def read(self, timeout: float) -> list:
        """Messages that arrive within `timeout` (returns as soon as something was read)."""
        if self.closed:
            return []
        ready, _, _ = select.select([self.sock], [], [], timeout)
        out = []
        while ready:
            try:
                data = self.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self.closed = True
                break
            if not data:  # TCP: the daemon closed the connection
                self.closed = True
                break
            out += [m for m in self.rx.parse_buffer(data) or [] if m.get_type() != "BAD_DATA"]
        return out

    def peer_closed(self) -> bool:
        """TCP: the daemon has closed this connection (end of stream waiting to be read)."""
        if self.closed or self.kind != "tcp":
            return self.closed
        try:
            ready, _, _ = select.select([self.sock], [], [], 0)
            self.closed = bool(ready) and self.sock.recv(1, socket.MSG_PEEK) == b""
        except OSError:
            self.closed = True
        return self.closed

    def request(self, msg, match: Callable, timeout: float = 3.0, resend_s: float = 1.0):
        """Send `msg` and wait for a reply that `match`es, sending again every `resend_s`."""
        end = time.monotonic() + timeout
        next_send = 0.0
        while time.monotonic() < end and not self.closed:
            if time.monotonic() >= next_send:
                self.send(msg)
                next_send = time.monotonic() + resend_s
            for m in self.read(min(0.05, max(0.0, end - time.monotonic()))):
                if match(m):
                    return m
        return None

    def close(self) -> None:
        self.closed = True
        self.sock.close()


class Monitor(threading.Thread):
    """The HEARTBEAT recorder (see the module docstring). `stop()` joins it."""

    def __init__(self, port: int, sysid: int = 253) -> None:
        super().__init__(name="stateful-monitor", daemon=True)
        self.station = Station("udp", port, sysid=sysid, compid=190)
        self.heartbeats: list[tuple[float, int, int]] = []  # (arrival, sysid, base_mode)
        self.texts: list[tuple[float, str]] = []
        self.started_at = time.monotonic()
        self._stop_event = threading.Event()
        self.lock = threading.Lock()

    def run(self) -> None:
        next_beat = 0.0
        while not self._stop_event.is_set():
            if time.monotonic() >= next_beat:
                self.station.send(GCS_HEARTBEAT)
                next_beat = time.monotonic() + 1.0
            for m in self.station.read(0.1):
                now = time.monotonic()
                kind = m.get_type()
                with self.lock:
                    if kind == "HEARTBEAT" and m.get_srcComponent() == 1 and m.type != M.MAV_TYPE_GCS:
                        self.heartbeats.append((now, m.get_srcSystem(), m.base_mode))
                    elif kind == "STATUSTEXT":
                        self.texts.append((now, m.text))

    def snapshot(self) -> tuple[list[tuple[float, int, int]], list[tuple[float, str]]]:
        with self.lock:
            return list(self.heartbeats), list(self.texts)

    def stop(self) -> None:
        self._stop_event.set()
        self.join(2.0)
        self.station.close()
