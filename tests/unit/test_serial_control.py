"""SERIAL_CONTROL passthrough core (issue 17, item 7): requests are bounded to one waiting per
device; a new one replaces the old; a send pass asks each port how much is waiting at most once."""

from __future__ import annotations

from types import SimpleNamespace

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.services.serialcontrol import CHUNK, SerialPassthrough

RESPOND = M.SERIAL_CONTROL_FLAG_RESPOND
GPS1, GPS2 = M.SERIAL_CONTROL_DEV_GPS1, M.SERIAL_CONTROL_DEV_GPS2


class FakePort:
    """A serial port: bytes the device sent wait in `incoming`; every in_waiting is an ioctl."""

    def __init__(self) -> None:
        self.incoming = bytearray()
        self.written = bytearray()
        self.ioctls = 0

    @property
    def in_waiting(self) -> int:
        self.ioctls += 1
        return len(self.incoming)

    def read(self, n: int) -> bytes:
        data = bytes(self.incoming[:n])
        del self.incoming[:n]
        return data

    def write(self, data: bytes) -> None:
        self.written += data

    def close(self) -> None:
        pass


def passthrough():
    ports: dict[str, FakePort] = {}

    def open_port(device, baud):
        return ports.setdefault(device, FakePort())

    config = [SimpleNamespace(port="gps1", device="/dev/a", baud=9600),
              SimpleNamespace(port="gps2", device="/dev/b", baud=9600)]
    return SerialPassthrough(config, open_port), ports


def request(device: int, data: bytes = b"", timeout_ms: int = 65535, flags: int = RESPOND):
    return M.MAVLink_serial_control_message(device, flags, timeout_ms, 0, len(data), list(data.ljust(CHUNK, b"\0")))


def test_many_requests_for_one_device_keep_one_waiting_and_one_ioctl_per_pass():
    sp, ports = passthrough()
    channel = object()
    for i in range(43_000):
        sp.handle(request(GPS1), (255, 190), channel, 100.0 + i * 1e-4)
    assert len(sp.waiting) == 1
    port = ports["/dev/a"]
    assert sp.replies(channel, 105.0) == [] and port.ioctls == 1
    port.incoming += b"x" * CHUNK  # a full chunk: the one waiting request is answered, once
    replies = sp.replies(channel, 105.1)
    assert [(r.device, r.count) for r in replies] == [(GPS1, CHUNK)]
    assert sp.waiting == {} and sp.next_deadline(105.1) is None


def test_a_new_request_replaces_the_waiting_one_and_gets_the_bytes_it_would_have():
    sp, ports = passthrough()
    first, second = object(), object()
    sp.handle(request(GPS1, b"ver\n", timeout_ms=1000), (255, 190), first, 10.0)
    sp.handle(request(GPS1, b"", timeout_ms=500), (254, 190), second, 10.2)
    ports["/dev/a"].incoming += b"v1.2\n"
    assert sp.replies(first, 20.0) == [], "the replaced request is not answered"
    replies = sp.replies(second, 10.8)
    assert [bytes(r.data[:r.count]) for r in replies] == [b"v1.2\n"]


def test_requests_for_different_devices_each_wait_and_the_total_is_bounded_by_the_devices():
    sp, ports = passthrough()
    channel = object()
    for _ in range(100):
        for device in (GPS1, GPS2, M.SERIAL_CONTROL_DEV_TELEM1):  # TELEM1 is not configured
            sp.handle(request(device, timeout_ms=100), (255, 190), channel, 1.0)
    assert sorted(sp.waiting) == [GPS1, GPS2]
    replies = sp.replies(channel, 1.2)  # timed out: both answered, empty
    assert sorted((r.device, r.count) for r in replies) == [(GPS1, 0), (GPS2, 0)]
    assert ports["/dev/a"].ioctls == 0 and ports["/dev/b"].ioctls == 0, "past the deadline nothing is asked"
