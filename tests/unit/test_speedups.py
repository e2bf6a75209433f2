"""The compiled fast path (gcsd.wire._speedups) against the Python it stands in for (gcsd.wire.speedups).

- feed: random streams of good, signed, MAVLink1, unknown-id, bad-CRC and bad-flag frames with
  garbage between them, cut into random chunks, through both parsers: the same frames (every
  slot), the same counters, the same per-source sequence table, the same held bytes, the same
  bad-CRC frames kept.
- RecentFrames: random sequences of seen / remember / check on both, the same answers, sizes and
  evictions.
- recv_batch: real UDP sockets on 127.0.0.1: order, sizes up to the largest datagram, two
  senders' addresses, the batch limit, nothing waiting, an ICMP error reported and then the data.
"""

from __future__ import annotations

import os
import select
import socket
import struct
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.routing import dedup
from gcsd.wire import codec, speedups
from gcsd.wire.codec import Encoder, FrameParser

needs_c = pytest.mark.skipif(speedups.compiled is None, reason="gcsd.wire._speedups is not built")
SLOTS = [s for s in codec.Frame.__slots__ if s != "_msg"]


def test_the_compiled_module_is_built_in_ci():
    """CI installs a C compiler and sets GCSD_REQUIRE_SPEEDUPS (.ci/run), so the compiled path is
    what its tests exercise."""
    if os.environ.get("GCSD_REQUIRE_SPEEDUPS") and not os.environ.get("GCSD_PURE_PYTHON"):
        assert speedups.IMPLEMENTATION == "c", "gcsd.wire._speedups was not built: is gcc installed?"
        assert codec._feed is speedups.compiled.feed


# --- feed ---------------------------------------------------------------------------------------

_MESSAGES = [
    M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3),
    M.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0),
    M.MAVLink_param_request_read_message(7, 0, b"SYSID_THISMAV", -1),
    M.MAVLink_mission_item_int_message(1, 190, 3, 0, 16, 0, 1, 0, 0, 0, 0, 473977000, 85455000, 10, 0),
    M.MAVLink_statustext_message(6, b"hello", 0, 0),
    M.MAVLink_file_transfer_protocol_message(0, 1, 1, bytes(251)),
]


def _piece(draw) -> bytes:
    kind = draw(st.sampled_from(["good", "good", "good", "v1", "signed", "unknown", "badcrc", "flags",
                                 "garbage", "truncated"]))
    sysid, compid = draw(st.integers(1, 255)), draw(st.integers(0, 255))
    enc = Encoder(sysid, compid)
    enc._mav.seq = draw(st.integers(0, 255))
    msg = draw(st.sampled_from(_MESSAGES))
    if kind == "v1":
        return enc.encode(msg, mavlink1=True)
    if kind == "signed":
        return enc.encode(msg, sign=(bytes(range(32)), 1, draw(st.integers(1, 2**40))))
    raw = enc.encode(msg)
    if kind == "unknown":
        payload = draw(st.binary(max_size=20))
        return struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, enc._mav.seq, sysid, compid, 42424, 0) + \
            payload + b"\x00\x00"
    if kind == "badcrc":
        return raw[:-1] + bytes([raw[-1] ^ 0x55])
    if kind == "flags":
        return raw[:2] + b"\x04" + raw[3:]
    if kind == "garbage":
        return draw(st.binary(min_size=1, max_size=12))
    if kind == "truncated":
        return raw[:draw(st.integers(1, len(raw) - 1))]
    return raw


@st.composite
def streams(draw):
    data = b"".join(_piece(draw) for _ in range(draw(st.integers(0, 12))))
    cuts = sorted(draw(st.lists(st.integers(0, len(data)), max_size=6)))
    chunks, last = [], 0
    for c in cuts + [len(data)]:
        chunks.append(data[last:c])
        last = c
    return chunks


def _run(feed, chunks, keep_bad: bool, datagram: bool):
    p = FrameParser(keep_bad_crc=keep_bad)
    out = []
    for chunk in chunks:
        frames = feed(p, chunk)
        out += [tuple(getattr(f, s) for s in SLOTS) for f in frames]
        if datagram and p.pending_bytes():
            p.reset()
    st_ = p.stats
    counters = (st_.frames, st_.bytes, st_.parse_errors, st_.crc_errors, st_.unknown_ids, st_.seq_gaps)
    return out, counters, st_.last_seq, p._buf, p.bad_crc_frames


@needs_c
@settings(max_examples=400, deadline=None)
@given(streams(), st.booleans(), st.booleans())
def test_the_compiled_feed_finds_what_the_python_feed_finds(chunks, keep_bad, datagram):
    assert _run(speedups.compiled.feed, chunks, keep_bad, datagram) == \
        _run(codec.feed_python, chunks, keep_bad, datagram)


@needs_c
def test_a_compiled_frame_is_a_frame():
    raw = Encoder(255, 190).encode(_MESSAGES[1])
    [f] = speedups.compiled.feed(FrameParser(), raw)
    assert type(f) is codec.Frame
    assert f.raw is raw  # one frame per datagram: the datagram's bytes, not a copy
    assert (f.name, f.signed, f.msg.command) == ("COMMAND_LONG", False, 400)
    f.sysid = 3  # its slots are ordinary slots
    assert f.sysid == 3


@needs_c
def test_the_sequence_table_is_bounded_and_sources_are_counted_apart():
    p = FrameParser()
    for sysid in range(1, 256):
        for compid in (1, 2):
            speedups.compiled.feed(p, Encoder(sysid, compid).encode(_MESSAGES[0]))
    assert len(p.stats.last_seq) == codec.MAX_SOURCES_TRACKED
    assert p.stats.frames == 510


def test_the_compiled_feed_is_what_the_parser_uses_when_built():
    expected = speedups.compiled.feed if speedups.compiled is not None else codec.feed_python
    assert codec._feed is expected


# --- recv_batch ---------------------------------------------------------------------------------

RECEIVERS = [
    pytest.param(speedups.recv_batch_python, id="python"),
    pytest.param(speedups.compiled.recv_batch if speedups.compiled else None, id="c", marks=needs_c),
]


@pytest.fixture
def udp():
    made = []

    def make(family=socket.AF_INET, host="127.0.0.1"):
        s = socket.socket(family, socket.SOCK_DGRAM)
        s.bind((host, 0))
        s.setblocking(False)
        made.append(s)
        return s

    yield make
    for s in made:
        s.close()


def _wait_readable(sock):
    select.select([sock], [], [], 2.0)


@pytest.mark.parametrize("recv_batch", RECEIVERS)
def test_datagrams_come_in_order_whole_and_with_their_senders(recv_batch, udp):
    rx, a, b = udp(), udp(), udp()
    sizes = [1, 44, 280, 1500, 9000, 65507]
    sent = []
    for i, size in enumerate(sizes * 2):
        payload = bytes([i]) * size
        (a if i % 2 else b).sendto(payload, rx.getsockname())
        sent.append((payload, (a if i % 2 else b).getsockname()))
    _wait_readable(rx)
    got = []
    deadline = time.monotonic() + 3.0
    while len(got) < len(sent) and time.monotonic() < deadline:
        batch = recv_batch(rx, 64)
        if not batch:
            _wait_readable(rx)
        got += batch
    assert got == sent
    assert recv_batch(rx, 64) == []  # nothing waiting: an empty batch, no exception


@pytest.mark.parametrize("recv_batch", RECEIVERS)
def test_a_batch_holds_at_most_n(recv_batch, udp):
    rx, tx = udp(), udp()
    for i in range(10):
        tx.sendto(bytes([i]), rx.getsockname())
    _wait_readable(rx)
    first = recv_batch(rx, 4)
    rest = recv_batch(rx, 64)
    assert [d for d, _ in first] == [bytes([i]) for i in range(4)]
    assert [d for d, _ in rest] == [bytes([i]) for i in range(4, 10)]


@pytest.mark.parametrize("recv_batch", RECEIVERS)
def test_an_icmp_error_is_raised_once_and_the_data_behind_it_still_comes(recv_batch, udp):
    rx, closed = udp(), udp()
    gone = closed.getsockname()
    closed.close()
    rx.connect(gone)  # as a udp-client channel's socket: ICMP errors are reported to it
    rx.send(b"x")  # port unreachable comes back as ECONNREFUSED
    deadline = time.monotonic() + 2.0
    raised = None
    while raised is None and time.monotonic() < deadline:
        try:
            recv_batch(rx, 8)
        except OSError as exc:
            raised = exc
    assert isinstance(raised, ConnectionRefusedError)
    back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)  # positive control: the peer comes up

    try:
        back.bind(gone)
        back.sendto(b"after", rx.getsockname())
        _wait_readable(rx)
        assert [d for d, _ in recv_batch(rx, 8)] == [b"after"]
    finally:
        back.close()


@pytest.fixture
def udp6(udp):
    try:
        return udp(socket.AF_INET6, "::1")
    except OSError:
        pytest.skip("no IPv6 loopback")


def test_an_ipv6_socket_is_read_by_the_python_receiver(udp, udp6):
    assert speedups.receiver(udp6) is speedups.recv_batch_python
    expected = speedups.compiled.recv_batch if speedups.compiled else speedups.recv_batch_python
    assert speedups.receiver(udp()) is expected


# --- send_batch ---------------------------------------------------------------------------------

def _received(rx, n: int, timeout_s: float = 3.0) -> list[bytes]:
    got: list[bytes] = []
    deadline = time.monotonic() + timeout_s
    while len(got) < n and time.monotonic() < deadline:
        _wait_readable(rx)
        got += [d for d, _ in speedups.recv_batch_python(rx, 64)]
    return got


SENDERS = [
    pytest.param(speedups.send_batch_python, id="python"),
    pytest.param(speedups.compiled.send_batch if speedups.compiled else None, id="c", marks=needs_c),
]


@pytest.mark.parametrize("send_batch", SENDERS)
def test_a_batch_goes_out_in_order_to_each_address(send_batch, udp):
    tx, a, b = udp(), udp(), udp()
    items = [(bytes([i]) * (1 + i * 7), (a if i % 3 else b).getsockname()) for i in range(150)]
    assert send_batch(tx, items) == 150  # more than one sendmmsg(2) holds (64 a call)
    for rx, want in ((a, [d for d, to in items if to == a.getsockname()]),
                     (b, [d for d, to in items if to == b.getsockname()])):
        assert _received(rx, len(want)) == want


@pytest.mark.parametrize("send_batch", SENDERS)
def test_a_datagram_the_kernel_refuses_is_dropped_and_the_rest_still_go(send_batch, udp):
    tx, rx = udp(), udp()
    too_big = b"x" * 70000  # EMSGSIZE: larger than any UDP datagram
    items = [(b"first", rx.getsockname()), (too_big, rx.getsockname()), (b"last", rx.getsockname())]
    assert send_batch(tx, items) == 2
    assert _received(rx, 2) == [b"first", b"last"]


def test_an_ipv6_socket_is_written_by_the_python_sender(udp, udp6):
    expected = speedups.compiled.send_batch if speedups.compiled else speedups.send_batch_python
    assert speedups.sender(udp6) is speedups.send_batch_python
    assert speedups.sender(udp()) is expected


# --- RecentFrames (dedup.py) -------------------------------------------------------------------

_OPS = st.lists(st.tuples(st.sampled_from(["seen", "remember", "check"]), st.integers(0, 5),
                          st.floats(0, 0.4, allow_nan=False)), max_size=60)


@needs_c
@settings(max_examples=300, deadline=None)
@given(_OPS, st.floats(0.05, 1.0), st.integers(1, 6))
def test_the_compiled_recent_frames_answer_as_the_python_ones(ops, window_s, max_frames):
    py = dedup.RecentFramesPython(window_s, max_frames)
    c = speedups.compiled.RecentFrames(window_s, max_frames)
    now = 0.0
    for op, key, dt in ops:
        now += dt
        raw = b"frame-%d" % key
        assert getattr(c, op)(raw, now) == getattr(py, op)(raw, now), (op, key, now)
        assert (len(c), c.evicted) == (len(py), py.evicted)


def test_the_compiled_recent_frames_are_used_when_built():
    assert dedup.RecentFrames is (speedups.compiled.RecentFrames if speedups.compiled else dedup.RecentFramesPython)


@needs_c
def test_a_recent_frames_never_initialised_refuses_instead_of_crashing():
    bare = speedups.compiled.RecentFrames.__new__(speedups.compiled.RecentFrames)
    with pytest.raises(RuntimeError):
        bare.seen(b"x", 1.0)
    assert len(bare) == 0
    for bad in (float("nan"), float("inf"), 0.0, -1.0):  # refused by both, as at every edge
        with pytest.raises(ValueError):
            speedups.compiled.RecentFrames(bad)
        with pytest.raises(ValueError):
            dedup.RecentFramesPython(bad)
