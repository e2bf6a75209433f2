"""Broadcast discovery: a udp-client channel with `broadcast: true` is found by a ground station
that does what QGroundControl's auto-connect does (bind a UDP port on every address, wait,
answer the first vehicle HEARTBEAT with its own, then talk to the vehicle).

Everything stays on loopback: the channel broadcasts to 127.255.255.255:PORT, which Linux
delivers to sockets bound to 0.0.0.0:PORT (as QGroundControl binds 14550) and not to sockets
bound to 127.0.0.1 (see gcsd.links.discovery). The listener reads each datagram's destination
address (IP_PKTINFO), so the test can tell broadcast from unicast.
"""

from __future__ import annotations

import select
import socket
import struct
import time

from pymavlink.dialects.v20 import ardupilotmega as M

from .helpers import VEHICLE, packed

IP_PKTINFO = getattr(socket, "IP_PKTINFO", 8)  # Linux
BROADCAST = "127.255.255.255"


class AutoConnectListener:
    """QGroundControl's side of auto-connect on a UDP port bound to every address."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.IPPROTO_IP, IP_PKTINFO, 1)
        self.sock.bind(("0.0.0.0", 0))
        self.port = self.sock.getsockname()[1]
        self.mav = M.MAVLink(None, srcSystem=255, srcComponent=190)
        self.mav.robust_parsing = True
        self.received: list[tuple[float, object, tuple[str, int], str]] = []  # (t, msg, source, destination)

    def read(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            if not select.select([self.sock], [], [], left)[0]:
                return
            data, ancdata, _, source = self.sock.recvmsg(65536, socket.CMSG_SPACE(12))
            destination = "?"
            for level, kind, cdata in ancdata:
                if level == socket.IPPROTO_IP and kind == IP_PKTINFO:
                    destination = socket.inet_ntoa(struct.unpack("i4s4s", cdata[:12])[2])
            for msg in self.mav.parse_buffer(data) or []:
                self.received.append((time.monotonic(), msg, source, destination))

    def wait_for(self, match, timeout: float = 5.0, since: int = 0):
        end = time.monotonic() + timeout
        while True:
            for record in self.received[since:]:
                if match(record):
                    return record
            since = len(self.received)
            if time.monotonic() >= end:
                return None
            self.read(min(0.05, end - time.monotonic()))

    def send(self, msg, to: tuple[str, int]) -> None:
        self.sock.sendto(packed(msg), to)

    def close(self) -> None:
        self.sock.close()


def from_vehicle(kind: str):
    return lambda r: r[1].get_type() == kind and (r[1].get_srcSystem(), r[1].get_srcComponent()) == VEHICLE


def gcs_heartbeat():
    return M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)


def broadcast_config(port: int) -> dict:
    return {"channels": [{"name": "lan", "type": "udp-client", "address": f"{BROADCAST}:{port}",
                          "broadcast": True}]}


def test_a_broadcast_channel_is_found_by_an_auto_connect_listener_and_then_talks_to_it_alone(daemon):
    qgc = AutoConnectListener()
    try:
        daemon(broadcast_config(qgc.port))
        first = qgc.wait_for(from_vehicle("HEARTBEAT"), timeout=5.0)
        assert first is not None, "no HEARTBEAT reached the listener"
        _, _, vehicle, destination = first
        assert destination == BROADCAST
        assert qgc.wait_for(from_vehicle("ATTITUDE")) is not None  # telemetry is broadcast too
        mark = len(qgc.received)
        qgc.send(gcs_heartbeat(), vehicle)
        qgc.send(M.MAVLink_command_long_message(*VEHICLE, M.MAV_CMD_REQUEST_MESSAGE, 0,
                                                M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0), vehicle)
        version = qgc.wait_for(from_vehicle("AUTOPILOT_VERSION"), since=mark)
        assert version is not None, "the vehicle did not answer the ground station"
        assert version[3] == "127.0.0.1" and version[2] == vehicle  # unicast, from the same socket
        qgc.read(1.5)  # the window for a broadcast after the lock, and on until a HEARTBEAT (1 Hz) came in it
        qgc.wait_for(lambda r: r[0] > version[0] and from_vehicle("HEARTBEAT")(r), since=mark)
        after = [r for r in qgc.received[mark:] if r[0] > version[0] and from_vehicle("HEARTBEAT")(r)]
        assert after and all(r[3] == "127.0.0.1" for r in after)
    finally:
        qgc.close()


def test_once_locked_the_channel_ignores_other_senders(daemon):
    qgc = AutoConnectListener()
    other = AutoConnectListener()  # a second ground station on the same LAN
    try:
        daemon(broadcast_config(qgc.port))
        first = qgc.wait_for(from_vehicle("HEARTBEAT"))
        assert first is not None
        vehicle = first[2]
        qgc.send(gcs_heartbeat(), vehicle)
        assert qgc.wait_for(lambda r: from_vehicle("HEARTBEAT")(r) and r[3] == "127.0.0.1") is not None
        read_sysid = M.MAVLink_param_request_read_message(*VEHICLE, b"SYSID_THISMAV", -1)
        mark_q, mark_o = len(qgc.received), len(other.received)
        other.send(read_sysid, vehicle)  # ignored: the channel is the station's now
        qgc.send(read_sysid, vehicle)  # positive control, in the same window
        assert qgc.wait_for(from_vehicle("PARAM_VALUE"), since=mark_q) is not None
        other.read(0.5)
        assert [r for r in other.received[mark_o:] if from_vehicle("PARAM_VALUE")(r)] == []
    finally:
        qgc.close()
        other.close()


def test_garbage_does_not_lock_the_channel_a_good_frame_does(daemon):
    qgc = AutoConnectListener()
    stray = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stray.bind(("127.0.0.1", 0))
    try:
        daemon(broadcast_config(qgc.port))
        first = qgc.wait_for(from_vehicle("HEARTBEAT"))
        assert first is not None
        vehicle = first[2]
        bad = bytearray(packed(gcs_heartbeat()))
        bad[-1] ^= 0xFF  # wrong CRC
        stray.sendto(bytes(bad) + b"\x00garbage", vehicle)
        sent_at = time.monotonic()
        still = qgc.wait_for(lambda r: from_vehicle("HEARTBEAT")(r) and r[0] > sent_at + 0.05, timeout=2.5)
        assert still is not None and still[3] == BROADCAST  # still broadcasting
        qgc.send(gcs_heartbeat(), vehicle)
        assert qgc.wait_for(lambda r: from_vehicle("HEARTBEAT")(r) and r[3] == "127.0.0.1",
                            timeout=3.0) is not None
    finally:
        stray.close()
        qgc.close()
