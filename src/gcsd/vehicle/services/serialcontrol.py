"""SERIAL_CONTROL passthrough to configured serial devices (REFERENCE.md section 11).

`serial_control` in the configuration maps SERIAL_CONTROL devices (TELEM1/TELEM2 = 0/1, GPS1/GPS2
= 2/3, SERIAL0..9 = 100..109) to serial ports of this machine. A request for a mapped device:
`baudrate` != 0 re-opens the port at that rate; its `count` data bytes are written; with RESPOND
the reply waits up to `timeout` ms for 70 bytes and then sends what arrived (flag REPLY only, up
to 70 bytes, possibly none), with MULTI further replies while full 70-byte chunks keep coming.
Requests with REPLY set, the SHELL device and unmapped devices are ignored, as ArduPilot does.
EXCLUSIVE is accepted and has nothing to lock (the devices are not gcsd's MAVLink channels).

Bounded: at most one request waits per device, so at most one per configured device in total. A
new request for a device replaces the one waiting there (unanswered; the bytes the device sent
stay in its buffer for the new one), as ArduPilot's single passthrough port serves one request
at a time: a ground station polls the console with a request after another, and only the latest
is worth answering. So a send pass reads (and asks the port how much is waiting, one ioctl) at
most once per configured device, however many requests came.

`SerialPassthrough` is the pure part: requests in, replies out, the next deadline; the ports are
objects with `read(n) -> bytes` (non-blocking), `write(data)` and `close()`, made by an injected
`open_port(device, baud)` (pyserial by default). A port that fails is closed and logged; the next
request opens it again.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import dataclass

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.services import Incoming, Service

log = structlog.get_logger("gcsd.serialcontrol")

DEVICE_IDS = {"telem1": 0, "telem2": 1, "gps1": 2, "gps2": 3, **{f"serial{n}": 100 + n for n in range(10)}}
CHUNK = 70
POLL_S = 0.01


@dataclass
class _Waiting:
    device: int
    requester: tuple[int, int]
    channel: object
    deadline_s: float
    multi: bool


class SerialPassthrough:
    def __init__(self, ports, open_port: Callable) -> None:
        self.config = {DEVICE_IDS[p.port]: p for p in ports}
        self.open_port = open_port
        self.ports: dict[int, object] = {}
        self.bauds: dict[int, int] = {}
        self.waiting: dict[int, _Waiting] = {}  # by device: the one request waiting there

    def handle(self, msg, requester: tuple[int, int], channel, now: float) -> None:
        if msg.flags & M.SERIAL_CONTROL_FLAG_REPLY or msg.device not in self.config:
            return
        port = self._port(msg.device, msg.baudrate)
        if port is None:
            return
        data = bytes(msg.data[:max(0, min(msg.count, CHUNK))])
        if data and not self._io(msg.device, lambda: port.write(data)):
            return
        if msg.flags & M.SERIAL_CONTROL_FLAG_RESPOND:
            self.waiting[msg.device] = _Waiting(msg.device, requester, channel, now + msg.timeout / 1000.0,
                                                bool(msg.flags & M.SERIAL_CONTROL_FLAG_MULTI))

    def _port(self, device: int, baud: int):
        cfg = self.config[device]
        want = baud or self.bauds.get(device, cfg.baud)
        port = self.ports.get(device)
        if port is not None and want != self.bauds.get(device):
            self._close(device)
            port = None
        if port is None:
            try:
                port = self.open_port(cfg.device, want)
            except Exception as exc:  # noqa: BLE001  (the device is missing, busy, not a tty...)
                log.warning("serial_control_open_failed", device=cfg.device, error=str(exc))
                return None
            self.ports[device], self.bauds[device] = port, want
        return port

    def _io(self, device: int, action) -> bool:
        try:
            action()
            return True
        except Exception as exc:  # noqa: BLE001  (a vanished device must not take the node down)
            log.warning("serial_control_io_failed", device=self.config[device].device, error=str(exc))
            self._close(device)
            return False

    def _read(self, device: int, port) -> bytes:
        try:
            return bytes(port.read(CHUNK))
        except Exception as exc:  # noqa: BLE001  (a vanished device must not take the node down)
            log.warning("serial_control_io_failed", device=self.config[device].device, error=str(exc))
            self._close(device)
            return b""

    def _close(self, device: int) -> None:
        port = self.ports.pop(device, None)
        if port is not None:
            with contextlib.suppress(Exception):  # closing a device that is gone: nothing left to do
                port.close()

    def replies(self, channel, now: float) -> list:
        """SERIAL_CONTROL replies due on `channel` now: a full chunk is waiting, or time is up."""
        out = []
        for w in list(self.waiting.values()):
            if w.channel is not channel:
                continue
            port = self.ports.get(w.device)
            if port is not None and now < w.deadline_s and getattr(port, "in_waiting", 0) < CHUNK:
                continue
            data = self._read(w.device, port) if port is not None else b""
            out.append(M.MAVLink_serial_control_message(w.device, M.SERIAL_CONTROL_FLAG_REPLY, 0, 0, len(data),
                                                        list(data.ljust(CHUNK, b"\0"))))
            if not (w.multi and len(data) == CHUNK):
                del self.waiting[w.device]
        return out

    def next_deadline(self, now: float) -> float | None:
        return now + POLL_S if self.waiting else None

    def close(self) -> None:
        for device in list(self.ports):
            self._close(device)


def open_serial(device: str, baud: int):
    import serial

    return serial.Serial(device, baud, timeout=0, write_timeout=0.5)


class SerialControlService(Service):
    def __init__(self, ctx, ports, open_port: Callable = open_serial) -> None:
        self.ctx = ctx
        self.passthrough = SerialPassthrough(ports, open_port)

    def handle_SERIAL_CONTROL(self, inc: Incoming) -> None:
        self.passthrough.handle(inc.msg, inc.sender, inc.channel, inc.now)
        self.ctx.wake(inc.channel)

    def pending(self, channel, now: float, send) -> float | None:
        for msg in self.passthrough.replies(channel, now):
            send(msg)
        return self.passthrough.next_deadline(now)
