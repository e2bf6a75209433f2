"""FTP through the real daemon with pymavlink clients: the capability bit, replies targeted at the
requester on the requesting channel only, and bursts held to a slow link's byte budget while the
link's telemetry slows down x4 and then recovers."""

from __future__ import annotations

import os
import struct
import time
from pathlib import Path

import pytest

from gcsd.vehicle.ftp.protocol import Op, Payload

from .helpers import VEHICLE, M, is_type, pump, rate_hz, udp_channel, udp_url, wait_for


def ftp_request(c, opcode: int, data: bytes = b"", size: int | None = None, offset: int = 0,
                seq: int = 0, session: int = 3) -> None:
    payload = Payload(seq, session, opcode, len(data) if size is None else size, 0, 0, offset, data).pack()
    c.send(M.MAVLink_file_transfer_protocol_message(0, *VEHICLE, payload))


def ftp_replies(c, since: int = 0) -> list[tuple[object, Payload]]:
    return [(r.msg, Payload.unpack(bytes(r.msg.payload))) for r in c.since(since, "FILE_TRANSFER_PROTOCOL")
            if r.src == VEHICLE]


def ftp_root(d) -> Path:
    return Path(d.config.state_dir) / d.config.ftp.root


def test_autopilot_version_advertises_ftp(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    mark = c.mark()
    c.command_long(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    version = wait_for(c, is_type("AUTOPILOT_VERSION", VEHICLE), since=mark)
    assert version is not None
    assert version.msg.capabilities & M.MAV_PROTOCOL_CAPABILITY_FTP


def test_a_reply_goes_only_to_the_requesting_channel_targeted_at_the_requester(daemon, client):
    d = daemon({"channels": [udp_channel("a"), udp_channel("b")]})
    a = client(udp_url(d.port("a")), sysid=255, compid=190)
    b = client(udp_url(d.port("b")), sysid=254, compid=191)
    for c in (a, b):
        c.heartbeat()
    for c in (a, b):  # both read (a UDP server answers only a peer it has read)
        assert wait_for(c, lambda r: r.src == VEHICLE, others=[a, b]), "a station's heartbeat was not read"
    mark_a, mark_b = a.mark(), b.mark()
    ftp_request(a, Op.LIST_DIRECTORY, b"/", seq=41)
    assert wait_for(a, is_type("FILE_TRANSFER_PROTOCOL", VEHICLE), since=mark_a) is not None
    # the control on b: a's next heartbeat is forwarded to b, after any wrong copy of the reply
    beat = a.heartbeat()
    assert wait_for(b, lambda r: r.raw == beat, since=mark_b, others=[a]) is not None
    [(msg, reply)] = ftp_replies(a, mark_a)
    assert (msg.target_network, msg.target_system, msg.target_component) == (0, 255, 190)
    assert (reply.seq, reply.req_opcode) == (42, Op.LIST_DIRECTORY)
    assert ftp_replies(b, mark_b) == []


def test_a_burst_on_a_57600_baud_link_keeps_to_the_budget_and_slows_telemetry_while_it_runs(daemon, client):
    budget = 5760
    d = daemon({"channels": [udp_channel("radio", bandwidth=budget)]})
    data = os.urandom(6000)
    (ftp_root(d) / "f.bin").write_bytes(data)
    c = client(udp_url(d.port("radio")))
    c.heartbeat()
    pump([c], 2.0)
    before = rate_hz([r for r in c.since(0, "ATTITUDE") if r.src == VEHICLE])
    assert before > 0

    mark = c.mark()
    ftp_request(c, Op.OPEN_FILE_RO, b"f.bin", seq=1)
    assert wait_for(c, is_type("FILE_TRANSFER_PROTOCOL", VEHICLE), since=mark) is not None
    c.chunks.clear()
    start = time.monotonic()
    ftp_request(c, Op.BURST_READ_FILE, size=239, seq=2)
    received, deadline = {}, start + 30.0
    while time.monotonic() < deadline and sum(len(v) for v in received.values()) < len(data):
        pump([c], 0.2)
        for _, p in ftp_replies(c, mark):
            if p.opcode == Op.ACK and p.req_opcode == Op.BURST_READ_FILE:
                received[p.offset] = p.data[:p.size]
    elapsed = time.monotonic() - start
    during = rate_hz([r for r in c.since(mark, "ATTITUDE") if r.src == VEHICLE])
    got = b"".join(received[k] for k in sorted(received))
    assert got == data, f"{len(got)} of {len(data)} bytes in {elapsed:.1f} s"
    total = sum(len(chunk) for chunk in c.chunks)
    # the token bucket may start with 100 ms of traffic; beyond that the budget holds
    assert total <= budget * elapsed + budget * 0.1 + 280, (total, elapsed)
    # a burst takes at most a third of the link: 26 packets of ~266 bytes at 1 920 B/s
    assert elapsed >= 26 * 266 / budget * 3 * 0.8, elapsed
    assert during <= before / 2, (before, during)

    pump([c], 1.5)  # streams go back to their rate 1 s after the last FTP reply
    mark = c.mark()
    pump([c], 2.0)
    after = rate_hz([r for r in c.since(mark, "ATTITUDE") if r.src == VEHICLE])
    assert after == pytest.approx(before, rel=0.2)


def test_the_ftp_root_is_created_under_the_state_directory(daemon):
    d = daemon({"channels": [udp_channel("gcs")], "ftp": {"root": "files/ftp"}})
    assert (Path(d.config.state_dir) / "files" / "ftp").is_dir()


def test_payload_struct_matches_the_wire_layout():
    raw = Payload(0x1234, 7, Op.READ_FILE, 9, 0, 0, 0x01020304, b"x").pack()
    assert struct.unpack_from("<HBBBBBxI", raw) == (0x1234, 7, Op.READ_FILE, 9, 0, 0, 0x01020304)
