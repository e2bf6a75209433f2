"""SERIAL_CONTROL passthrough to a configured serial device, over a PTY pair: a ground station
writes bytes to "GPS1" and reads its answer; REPLY packets, unmapped devices and SHELL are ignored."""

from __future__ import annotations

import os
import time
import tty

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from .helpers import pump, udp_channel, udp_url, wait_for

FLAGS = M.SERIAL_CONTROL_FLAG_RESPOND | M.SERIAL_CONTROL_FLAG_EXCLUSIVE


@pytest.fixture
def gps1(daemon, client):
    """A daemon whose GPS1 is one end of a PTY pair, a ground station that said hello, and the
    other end of the PTY (non-blocking): (daemon, gcs, master fd)."""
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    try:
        d = daemon({"channels": [udp_channel("gcs")],
                    "serial_control": [{"port": "gps1", "device": os.ttyname(slave), "baud": 9600}]})
        gcs = client(udp_url(d.port("gcs")))
        gcs.heartbeat()
        yield d, gcs, master
    finally:
        os.close(master)
        os.close(slave)


def _request(device: int, data: bytes, flags: int = FLAGS, timeout_ms: int = 300, baud: int = 0):
    return M.MAVLink_serial_control_message(device, flags, timeout_ms, baud, len(data), list(data.ljust(70, b"\0")))


def test_serial_control_writes_to_the_device_and_replies_with_what_it_answers(gps1):
    _, gcs, master = gps1
    mark = gcs.mark()
    gcs.send(_request(M.SERIAL_CONTROL_DEV_GPS1, b"$PMTK605*31\r\n", timeout_ms=500))
    got = bytearray()
    deadline = time.monotonic() + 5.0  # the request's bytes are awaited, not expected within 0.4 s
    while not got.endswith(b"\r\n") and time.monotonic() < deadline:
        pump([gcs], 0.02)
        try:
            got += os.read(master, 1024)
        except BlockingIOError:
            pass
    assert bytes(got) == b"$PMTK605*31\r\n"
    os.write(master, b"$PMTK705,AXN_5.1*2B\r\n")
    reply = wait_for(gcs, lambda r: r.type == "SERIAL_CONTROL", 3.0, mark)
    assert reply is not None and reply.src == (1, 1)
    assert reply.msg.flags == M.SERIAL_CONTROL_FLAG_REPLY and reply.msg.device == M.SERIAL_CONTROL_DEV_GPS1
    assert bytes(reply.msg.data[:reply.msg.count]) == b"$PMTK705,AXN_5.1*2B\r\n"

    mark = gcs.mark()
    gcs.send(_request(M.SERIAL_CONTROL_DEV_GPS1, b"", timeout_ms=100))
    empty = wait_for(gcs, lambda r: r.type == "SERIAL_CONTROL", 3.0, mark)
    assert empty is not None and empty.msg.count == 0  # nothing arrived within the timeout

    mark = gcs.mark()
    gcs.send(_request(M.SERIAL_CONTROL_DEV_GPS2, b"x"))  # not configured
    gcs.send(_request(M.SERIAL_CONTROL_DEV_SHELL, b"ls\n"))
    gcs.send(_request(M.SERIAL_CONTROL_DEV_GPS1, b"y", flags=M.SERIAL_CONTROL_FLAG_REPLY))
    # the control, just after on the same socket: a good request is answered (empty) after its
    # 400 ms timeout, later than a wrong reply to one of the three (timeouts 300 ms) would come
    gcs.send(_request(M.SERIAL_CONTROL_DEV_GPS1, b"", timeout_ms=400))
    assert wait_for(gcs, lambda r: r.type == "SERIAL_CONTROL", 3.0, mark) is not None
    replies = gcs.since(mark, "SERIAL_CONTROL")
    assert [(r.msg.device, r.msg.count) for r in replies] == [(M.SERIAL_CONTROL_DEV_GPS1, 0)]


def test_a_flood_of_waiting_requests_keeps_one_per_device_and_the_daemon_idle(gps1):
    """43 000 requests with RESPOND and the longest timeout used to pile up and be walked with an
    ioctl each, 100 times a second (issue 17, item 7)."""
    _, gcs, master = gps1
    flood = _request(M.SERIAL_CONTROL_DEV_GPS1, b"", timeout_ms=65535)
    for _ in range(20):
        for _ in range(500):
            gcs.send(flood)
        pump([gcs], 0.01)  # let the daemon read its socket
    pump([gcs], 0.5)
    cpu_before, wall_before = time.process_time(), time.monotonic()
    pump([gcs], 2.0)
    cpu_share = (time.process_time() - cpu_before) / (time.monotonic() - wall_before)
    mark = gcs.mark()
    gcs.send(_request(M.SERIAL_CONTROL_DEV_GPS1, b"", timeout_ms=300))  # the control: answered
    os.write(master, b"$GPGGA\r\n")
    reply = wait_for(gcs, lambda r: r.type == "SERIAL_CONTROL", 3.0, mark)
    assert reply is not None and bytes(reply.msg.data[:reply.msg.count]) == b"$GPGGA\r\n"
    assert len(gcs.since(mark, "SERIAL_CONTROL")) == 1, "the replaced requests are not answered"
    assert cpu_share < 0.25, f"the test process (daemon and client) used {cpu_share:.0%} of a core"
