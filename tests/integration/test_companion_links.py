"""Links that come back (SPEC.md "Companion routing"): host names resolved at every (re)connect,
a serial device removed and re-created under the same by-id style link, and a baud list cycled
until a good frame arrives. Real sockets and PTY pairs."""

from __future__ import annotations

import os
import socket
import termios
import time

import pytest

from .helpers import VEHICLE, M, from_vehicle, packed, read_fd, udp_channel, udp_url, wait_for
from .test_serial import Pty

FC = (7, 1)
HEARTBEAT = M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0, 3)


def _parse(raw: bytes) -> list:
    parser = M.MAVLink(None)
    parser.robust_parsing = True
    return [m for m in parser.parse_buffer(raw) or [] if m.get_type() != "BAD_DATA"]


def _vehicle_heartbeat(raw: bytes) -> bool:
    return any(m.get_type() == "HEARTBEAT" and (m.get_srcSystem(), m.get_srcComponent()) == VEHICLE
               for m in _parse(raw))


def _channel(d, name: str) -> dict:
    return next(c for c in d.status()["channels"] if c["name"] == name)


def _poll(condition, timeout_s: float, step_s: float = 0.05) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(step_s)
    return condition()


# --- host names ----------------------------------------------------------------------------

def test_localhost_as_a_host_name_for_udp_and_tcp_clients(daemon):
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    udp.bind(("127.0.0.1", 0))
    tcp = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    tcp.bind(("127.0.0.1", 0))
    tcp.listen(1)
    try:
        daemon({"channels": [
            {"name": "up", "type": "udp-client", "address": f"localhost:{udp.getsockname()[1]}"},
            {"name": "tcp", "type": "tcp-client", "address": f"localhost:{tcp.getsockname()[1]}"},
        ]})
        udp.settimeout(3.0)
        got = bytearray()
        deadline = time.monotonic() + 3.0
        while not _vehicle_heartbeat(bytes(got)) and time.monotonic() < deadline:
            got += udp.recv(65536)
        assert _vehicle_heartbeat(bytes(got))
        tcp.settimeout(3.0)
        conn, _ = tcp.accept()
        with conn:
            conn.setblocking(False)
            stream = bytearray()
            read_fd(conn.fileno(), 1.5, stream)
            assert _vehicle_heartbeat(bytes(stream))
    finally:
        udp.close()
        tcp.close()


def test_a_name_that_does_not_resolve_is_retried_and_stops_nothing(daemon, client):
    d = daemon({"channels": [udp_channel("gcs"),
                             {"name": "lte", "type": "udp-client", "address": "fc-modem.invalid:14550"}]})
    gcs = client(udp_url(d.port("gcs")), 255, 190)
    gcs.heartbeat()
    assert wait_for(gcs, from_vehicle)  # the other channel works
    assert _channel(d, "lte")["peers"] == 0
    # tried again with the backoff (0.5 s, then 1 s, ...): a second failed lookup within 3 s
    assert _poll(lambda: _channel(d, "lte")["open_failures"] >= 2, 3.0)
    gcs.heartbeat()
    assert wait_for(gcs, from_vehicle, since=gcs.mark())


# --- serial devices that come back ------------------------------------------------------------

class LinkedPty(Pty):
    """test_serial's PTY pair (frames sent as the flight controller), its slave reachable through a
    by-id style symlink the test controls."""

    def __init__(self, link: str) -> None:
        super().__init__()
        self.link = link
        os.symlink(self.path, link)

    def send(self, msg) -> None:
        os.write(self.master, packed(msg, *FC))

    def speed(self) -> int:
        return termios.tcgetattr(self.slave)[5]  # ospeed, as the daemon set it

    def remove(self) -> None:
        os.unlink(self.link)
        self.close()


@pytest.fixture
def ptys():
    made: list[LinkedPty] = []
    yield made
    for p in made:
        if os.path.lexists(p.link):
            p.remove()


def _answered(p: LinkedPty, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        p.send(HEARTBEAT)
        p.read(0.2)
        if _vehicle_heartbeat(bytes(p.raw)):
            return True
    return False


def test_a_serial_device_removed_and_recreated_under_the_same_link_is_opened_again(daemon, ptys, tmp_path):
    link = str(tmp_path / "usb-ArduPilot_fmuv3-if00")
    ptys.append(LinkedPty(link))
    d = daemon({"channels": [{"name": "fc", "type": "serial", "device": link}, udp_channel("gcs")]})
    assert _answered(ptys[0], 3.0)
    ptys[0].remove()  # unplugged: the link goes, the device goes
    assert _poll(lambda: _channel(d, "fc")["peers"] == 0, 5.0), "the daemon never saw the device go"
    ptys.append(LinkedPty(link))  # plugged in again: a new tty behind the same link
    assert _answered(ptys[1], 10.0), "the device was not opened again"
    # The vehicle's HEARTBEAT proves the device is open; our own may have been read a moment later.
    assert _poll(lambda: _heard(ptys[1], d), 5.0), "the flight controller's side was not admitted as a peer"


def _accepted(p: LinkedPty, d) -> bool:
    p.send(HEARTBEAT)
    return _channel(d, "fc")["packets_in"] >= 1


def _heard(p: LinkedPty, d) -> bool:
    p.send(HEARTBEAT)
    return _channel(d, "fc")["peers"] == 1


def test_a_serial_device_missing_at_start_is_opened_when_it_appears(daemon, ptys, tmp_path):
    link = str(tmp_path / "usb-ArduPilot_fmuv3-if00")
    d = daemon({"channels": [{"name": "fc", "type": "serial", "device": link}, udp_channel("gcs")]})
    assert _channel(d, "fc")["peers"] == 0  # started all the same: the daemon is ready
    ptys.append(LinkedPty(link))
    assert _answered(ptys[0], 10.0), "the device was not opened when it appeared"


def test_a_baud_list_is_cycled_until_a_good_frame_and_then_kept(daemon, ptys, tmp_path):
    link = str(tmp_path / "usb-radio")
    p = LinkedPty(link)
    ptys.append(p)
    d = daemon({"channels": [{"name": "fc", "type": "serial", "device": link, "baud": [921600, 57600]}]})
    assert p.speed() == termios.B921600
    # the "flight controller" speaks only 57600: nothing good reaches the daemon until it moves there
    assert _poll(lambda: p.speed() == termios.B57600, 5.0), "the daemon never tried the second baud"
    assert _answered(p, 3.0)
    # The vehicle's HEARTBEAT may precede the daemon reading ours (pyserial flushes the input when it
    # opens, after setting the speed): a frame of ours is awaited, as a 1 Hz flight controller's would be.
    assert _poll(lambda: _accepted(p, d), 1.5), "no frame of ours was accepted at 57600"
    time.sleep(2.5)  # longer than a probe: a locked baud stays
    assert p.speed() == termios.B57600
    p.raw.clear()
    assert _answered(p, 2.0)  # and is still served
