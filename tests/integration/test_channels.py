"""Channel transports (SPEC.md "Channels"): several clients on one UDP or TCP server, TCP and UDP
client channels that reach out to a test-owned socket, reconnection, and the output version that
follows the peer. Forgetting a UDP client silent for 30 s is too slow for real time: it is tested
with a float clock in tests/unit/test_channel.py.
"""

from __future__ import annotations

import contextlib
import socket
import time

from pymavlink.dialects.v10 import ardupilotmega as mavlink1

from .helpers import (
    VEHICLE,
    M,
    free_listener,
    from_vehicle,
    is_ack,
    pump_until,
    tcp_channel,
    tcp_url,
    udp_channel,
    udp_url,
    wait_for,
)

HEARTBEAT_WAIT_S = 2.5  # HEARTBEAT is 1 Hz: a new peer may wait up to a second for the next one


def is_vehicle_heartbeat(r) -> bool:
    return r.type == "HEARTBEAT" and r.src == VEHICLE


def _parse(data: bytes, version: int = 2) -> list:
    mav = (M if version == 2 else mavlink1).MAVLink(None)
    mav.robust_parsing = True
    return [m for m in mav.parse_buffer(data) or [] if m.get_type() != "BAD_DATA"]


def _source(frame: bytes) -> tuple[int, int]:
    """(sysid, compid) from a frame's header, MAVLink1 or 2."""
    return (frame[5], frame[6]) if frame[0] == 0xFD else (frame[3], frame[4])


def _recv_datagrams(sock: socket.socket, seconds: float) -> list[bytes]:
    sock.settimeout(0.05)
    out = []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        with contextlib.suppress(TimeoutError):
            out.append(sock.recv(65536))
    return out


def _recv_stream(sock: socket.socket, seconds: float) -> bytes:
    sock.settimeout(0.05)
    out = bytearray()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        with contextlib.suppress(TimeoutError):
            data = sock.recv(65536)
            if not data:
                break
            out += data
    return bytes(out)


# --- servers with several clients -----------------------------------------------------------

def test_udp_server_answers_two_clients_on_one_port(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    first = client(udp_url(d.port("gcs")), 255, 190)
    second = client(udp_url(d.port("gcs")), 254, 190)
    for c in (first, second):
        c.heartbeat()
    for c in (first, second):
        assert wait_for(c, is_vehicle_heartbeat, timeout=HEARTBEAT_WAIT_S, others=[first, second])
    mark = second.mark()
    second.command_long(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)
    assert wait_for(second, is_ack(M.MAV_CMD_GET_MESSAGE_INTERVAL), since=mark, others=[first])
    assert d.stats("gcs")["peers"] == 2


def test_tcp_server_accepts_two_clients_at_once(daemon, client):
    d = daemon({"channels": [tcp_channel("gcs")]})
    first = client(tcp_url(d.port("gcs")), 255, 190)
    second = client(tcp_url(d.port("gcs")), 254, 190)
    for c in (first, second):  # a TCP peer is known from its connection: no need to speak first
        assert wait_for(c, is_vehicle_heartbeat, timeout=HEARTBEAT_WAIT_S, others=[first, second])
    for c in (first, second):
        mark = c.mark()
        c.command_long(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)
        assert wait_for(c, is_ack(M.MAV_CMD_GET_MESSAGE_INTERVAL), since=mark, others=[first, second])
    assert d.stats("gcs")["peers"] == 2


def test_tcp_server_keeps_serving_after_a_client_leaves(daemon, client):
    d = daemon({"channels": [tcp_channel("gcs")]})
    leaving = client(tcp_url(d.port("gcs")), 255, 190)
    staying = client(tcp_url(d.port("gcs")), 254, 190)
    assert wait_for(leaving, from_vehicle, others=[staying])
    leaving.close()
    mark = staying.mark()
    # the closed connection is awaited (under load the daemon may read its EOF late), and the
    # staying client keeps being served meanwhile
    assert pump_until([staying], lambda: d.stats("gcs")["peers"] == 1 and staying.since(mark, "HEARTBEAT"),
                      at_least_s=1.2), (d.stats("gcs"), [r.type for r in staying.since(mark)])


# --- client channels ------------------------------------------------------------------------

def test_tcp_client_connects_and_reconnects_after_the_connection_is_closed(daemon):
    listener = free_listener(socket.SOCK_STREAM)
    conns: list[socket.socket] = []
    try:
        listener.settimeout(5.0)
        port = listener.getsockname()[1]
        daemon({"channels": [{"name": "up", "type": "tcp-client", "address": f"127.0.0.1:{port}"}]})
        conn, _ = listener.accept()
        conns.append(conn)
        first = _parse(_recv_stream(conn, 1.3))
        assert any(m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1 for m in first)

        conn.close()
        closed_at = time.monotonic()
        listener.settimeout(3.0)
        again, _ = listener.accept()
        conns.append(again)
        assert time.monotonic() - closed_at <= 2.0
        second = _parse(_recv_stream(again, 1.3))
        assert any(m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1 for m in second)
    finally:
        for s in (*conns, listener):
            s.close()


def test_udp_client_sends_heartbeats_to_its_remote(daemon):
    remote = free_listener(socket.SOCK_DGRAM)
    try:
        port = remote.getsockname()[1]
        daemon({"channels": [{"name": "out", "type": "udp-client", "address": f"127.0.0.1:{port}"}]})
        msgs = _parse(b"".join(_recv_datagrams(remote, 2.2)))
        beats = [m for m in msgs if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1]
        assert len(beats) >= 2
        assert beats[0].autopilot == M.MAV_AUTOPILOT_ARDUPILOTMEGA
    finally:
        remote.close()


# --- output version -------------------------------------------------------------------------

def test_output_follows_the_peer_version(daemon, client):
    d = daemon({"channels": [udp_channel("v1"), udp_channel("v2")]})
    old = client(udp_url(d.port("v1")), 255, 190, version=1)
    new = client(udp_url(d.port("v2")), 254, 190, version=2)
    for c in (old, new):
        c.heartbeat()
    for c in (old, new):
        assert wait_for(c, is_vehicle_heartbeat, timeout=HEARTBEAT_WAIT_S, others=[old, new])
    new_heartbeat = new.heartbeat()  # forwarded to the v1 channel too: unchanged, never converted
    assert wait_for(old, lambda r: r.raw == new_heartbeat, others=[new]), "the MAVLink2 heartbeat was not forwarded"
    from_vehicle_to_old = [chunk for chunk in old.chunks if _source(chunk) == VEHICLE]
    from_vehicle_to_new = [chunk for chunk in new.chunks if _source(chunk) == VEHICLE]
    assert from_vehicle_to_old and {chunk[0] for chunk in from_vehicle_to_old} == {0xFE}
    assert from_vehicle_to_new and {chunk[0] for chunk in from_vehicle_to_new} == {0xFD}
    assert new_heartbeat in old.chunks
    mark = old.mark()
    old.command_long(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)
    ack = wait_for(old, lambda r: r.type == "COMMAND_ACK" and r.src == VEHICLE, since=mark, others=[new])
    assert ack is not None and ack.raw[0] == 0xFE


def test_mavlink1_channel_starts_in_mavlink1_before_hearing_anything(daemon):
    remote = free_listener(socket.SOCK_DGRAM)
    try:
        port = remote.getsockname()[1]
        daemon({"channels": [{"name": "out", "type": "udp-client", "address": f"127.0.0.1:{port}",
                              "mavlink": 1}]})
        datagrams = _recv_datagrams(remote, 1.5)
        assert datagrams and {d[0] for d in datagrams} == {0xFE}
        msgs = _parse(b"".join(datagrams), version=1)
        assert any(m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1 for m in msgs)
    finally:
        remote.close()


def test_mavlink1_channel_switches_to_mavlink2_when_the_peer_speaks_it(daemon, client):
    d = daemon({"channels": [udp_channel("gcs", mavlink=1)]})
    c = client(udp_url(d.port("gcs")), 255, 190, version=2)
    c.heartbeat()
    assert wait_for(c, is_vehicle_heartbeat, timeout=HEARTBEAT_WAIT_S)
    assert {chunk[0] for chunk in c.chunks if _source(chunk) == VEHICLE} == {0xFD}
