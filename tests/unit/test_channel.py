"""Channel and TokenBucket with a float clock: the byte budget (capacity, refill, drops counted),
admission of a udp-server's sources, and UDP peer expiry (silent 30 s, swept once a second).

No sockets and no event loop: a peer's writer is a list the test reads, datagrams go in through
`Channel.receive` as the UDP transport hands them over (an unknown address is a `stranger`), and
`now` is a float the test sets. Frames are real MAVLink bytes packed by pymavlink.
"""

from __future__ import annotations

import pytest
import yaml
from pymavlink.dialects.v10 import ardupilotmega as mavlink1
from pymavlink.dialects.v20 import ardupilotmega as M
from receivers import Recorder

from gcsd.config import parse_config
from gcsd.links.channel import MAX_FRAME_BYTES, UDP_PEER_TIMEOUT_S, Channel
from gcsd.links.outbox import TokenBucket

T0 = 1000.0
handed_on: dict[Channel, list] = {}


class Clock:
    def __init__(self, t: float = T0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def packed(msg, sysid: int = 255, compid: int = 190, version: int = 2) -> bytes:
    mav = (M if version == 2 else mavlink1).MAVLink(None, srcSystem=sysid, srcComponent=compid)
    return bytes(msg.pack(mav))


HEARTBEAT = packed(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
HEARTBEAT_V1 = packed(mavlink1.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3),
                      version=1)
RADIO_STATUS = packed(M.MAVLink_radio_status_message(200, 200, 40, 0, 0, 0, 0), 51, 68)
GARBAGE = bytes(range(7, 60))


def make_channel(clock: Clock, receiver: Recorder | None = None, **extra) -> tuple[Channel, dict[object, list[bytes]]]:
    """A udp-server channel; returns it and what each admitted peer was sent. The frames it hands
    on are in `handed_on[channel]`."""
    conf = {"channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0", **extra}]}
    config = parse_config(yaml.safe_dump(conf), "test.yaml")
    receiver = receiver or Recorder()
    ch = Channel(0, config.channels[0], clock, receiver=receiver)
    sent: dict[object, list[bytes]] = {}
    handed_on[ch] = receiver.frames

    def make_writer(key):
        out = sent.setdefault(key, [])
        return lambda data: out.append(data) or True

    ch.make_writer = make_writer
    return ch, sent


def datagram(ch: Channel, addr, data: bytes, now: float) -> None:
    """What the UDP transport does with one datagram from addr."""
    peer = ch.peers.get(addr) or ch.stranger(addr, now)
    ch.receive(peer, data, now, datagram=True)


def sweep_until(ch: Channel, start: float, end: float, step: float = 0.25) -> dict[float, list]:
    """Run the transport's sweep every `step` seconds; returns {time: forgotten peers} when any."""
    gone = {}
    t = start
    while t <= end + 1e-9:
        forgotten = ch.sweep(t)
        if forgotten:
            gone[t] = forgotten
        t = round(t + step, 6)
    return gone


# --- TokenBucket --------------------------------------------------------------------------

def test_bucket_starts_full_with_100_ms_of_traffic():
    bucket = TokenBucket(10_000, T0)
    assert bucket.capacity == 1000
    assert bucket.try_take(1000, T0)
    assert not bucket.try_take(1, T0)


def test_bucket_holds_at_least_one_maximal_frame_on_a_slow_link():
    bucket = TokenBucket(960, T0)  # 9600 baud
    assert bucket.capacity == MAX_FRAME_BYTES
    assert bucket.try_take(MAX_FRAME_BYTES, T0)


def test_bucket_refills_at_its_rate_and_never_beyond_capacity():
    bucket = TokenBucket(10_000, T0)
    assert bucket.try_take(1000, T0)
    assert not bucket.try_take(201, T0 + 0.02)  # 200 bytes back after 20 ms
    assert bucket.try_take(199, T0 + 0.02)
    assert bucket.wait_s(501, T0 + 0.02) == pytest.approx(0.05, abs=1e-6)  # 1 byte left: 500 to come
    assert bucket.try_take(1000, T0 + 3600.0)  # an hour idle: still only 100 ms worth
    assert not bucket.try_take(1, T0 + 3600.0)


def test_bucket_does_not_refill_when_the_clock_goes_back():
    bucket = TokenBucket(10_000, T0)
    assert bucket.try_take(1000, T0)
    assert not bucket.try_take(1, T0 - 5.0)
    assert not bucket.try_take(101, T0 + 0.01)  # 10 ms after T0, not after T0 - 5 s
    assert bucket.try_take(99, T0 + 0.01)


def test_bucket_wait_is_zero_when_the_bytes_are_there():
    bucket = TokenBucket(10_000, T0)
    assert bucket.wait_s(1000, T0) == 0.0


# --- the channel's budget -------------------------------------------------------------------

def test_channel_without_bandwidth_sends_everything():
    clock = Clock()
    ch, sent = make_channel(clock)
    datagram(ch, ("10.0.0.1", 5), HEARTBEAT, clock.t)
    for _ in range(5000):
        assert ch.write(HEARTBEAT)
    assert len(sent[("10.0.0.1", 5)]) == 5000
    assert ch.snapshot()["drops"] == 0


def test_frames_beyond_the_budget_are_dropped_counted_and_not_sent():
    clock = Clock()
    ch, sent = make_channel(clock, bandwidth=1000)  # 280 bytes of capacity (one maximal frame)
    addr = ("10.0.0.1", 5)
    datagram(ch, addr, HEARTBEAT, clock.t)
    results = [ch.write(HEARTBEAT) for _ in range(30)]
    fits = MAX_FRAME_BYTES // len(HEARTBEAT)
    assert results == [True] * fits + [False] * (30 - fits)
    snap = ch.snapshot()
    assert (len(sent[addr]), snap["drops"], snap["packets_out"]) == (fits, 30 - fits, fits)
    assert snap["bytes_out"] == fits * len(HEARTBEAT)


def test_budget_refills_with_the_clock():
    clock = Clock()
    ch, _sent = make_channel(clock, bandwidth=1000)
    addr = ("10.0.0.1", 5)
    datagram(ch, addr, HEARTBEAT, clock.t)
    while ch.write(HEARTBEAT):
        pass
    assert not ch.has_room(len(HEARTBEAT))
    assert ch.budget_wait_s(len(HEARTBEAT)) > 0
    clock.t += ch.budget_wait_s(len(HEARTBEAT))
    ch.tick(clock.t, 0.0)  # the asyncio layer's next wake-up
    assert ch.has_room(len(HEARTBEAT))
    assert ch.write(HEARTBEAT)


def test_sustained_output_keeps_to_the_budget():
    clock = Clock()
    ch, sent = make_channel(clock, bandwidth=5760)  # 57600 baud
    addr = ("10.0.0.1", 5)
    datagram(ch, addr, HEARTBEAT, clock.t)
    offered = 0
    for _ in range(10_000):  # 10 s, twice the budget offered in 1 ms steps
        clock.t += 0.001
        ch.tick(clock.t, 0.0)
        for _ in range(2 if offered % 5 else 1):
            ch.write(HEARTBEAT)
            offered += 1
    out = sum(len(d) for d in sent[addr])
    assert 5760 * 10 - len(HEARTBEAT) <= out <= 5760 * 10 + 576 + len(HEARTBEAT)
    snap = ch.snapshot()
    assert snap["drops"] == offered - len(sent[addr]) > 0


def test_a_peer_whose_writer_is_full_counts_a_drop():
    clock = Clock()
    ch, _sent = make_channel(clock)
    ch.make_writer = lambda key: lambda data: False  # the socket's buffer is full
    datagram(ch, ("10.0.0.1", 5), HEARTBEAT, clock.t)
    assert not ch.write(HEARTBEAT)
    snap = ch.snapshot()
    assert (snap["drops"], snap["packets_out"]) == (1, 0)


# --- admission ------------------------------------------------------------------------------

def test_a_good_frame_admits_its_sender_and_garbage_admits_nobody():
    clock = Clock()
    ch, sent = make_channel(clock)
    datagram(ch, ("10.0.0.9", 9), GARBAGE, clock.t)
    datagram(ch, ("10.0.0.8", 8), b"\xfd", clock.t)
    assert ch.snapshot()["peers"] == 0
    ch.write(HEARTBEAT)
    assert sent == {}, "nothing goes to a source that never sent a good frame"
    datagram(ch, ("10.0.0.1", 5), HEARTBEAT, clock.t)
    assert ch.snapshot()["peers"] == 1
    assert ch.write(HEARTBEAT) and list(sent) == [("10.0.0.1", 5)]
    assert ch.snapshot()["parse_errors"] > 0


def test_radio_status_alone_does_not_admit_a_source():
    clock = Clock()
    ch, _sent = make_channel(clock)
    datagram(ch, ("10.0.0.2", 2), RADIO_STATUS, clock.t)
    assert ch.snapshot()["peers"] == 0
    assert len(handed_on.pop(ch)) == 1, "but it is handed on (the vehicle reads RADIO_STATUS)"


def test_a_frame_that_fails_verification_admits_nobody_and_is_not_handed_on():
    clock = Clock()
    receiver = Recorder("unsigned")
    ch, _sent = make_channel(clock, receiver)
    datagram(ch, ("10.0.0.1", 5), HEARTBEAT, clock.t)
    assert receiver.rejects == ["unsigned"]
    assert handed_on.pop(ch) == []
    snap = ch.snapshot()
    assert (snap["peers"], snap["packets_in"]) == (0, 0)


def test_more_than_max_peers_replaces_the_one_silent_longest():
    clock = Clock()
    ch, sent = make_channel(clock)
    n = ch.max_peers
    for i in range(n):
        clock.t += 1.0
        datagram(ch, ("10.0.0.1", 100 + i), HEARTBEAT, clock.t)
    clock.t += 1.0
    datagram(ch, ("10.0.0.1", 100), HEARTBEAT, clock.t)  # the first speaks again: 101 is now the oldest
    datagram(ch, ("10.0.0.1", 999), HEARTBEAT, clock.t)
    assert ch.snapshot()["peers"] == n
    assert ch.snapshot()["peers_replaced"] == 1
    ch.write(HEARTBEAT)
    got = {addr[1] for addr, out in sent.items() if out}
    assert 101 not in got and {100, 999} <= got


# --- UDP peer expiry ------------------------------------------------------------------------

def test_a_udp_peer_silent_for_30_s_is_forgotten_within_the_next_second():
    clock = Clock()
    ch, _sent = make_channel(clock)
    datagram(ch, ("10.0.0.1", 5), HEARTBEAT, T0)
    gone = sweep_until(ch, T0, T0 + 40.0)
    assert list(gone.values()) == [[("10.0.0.1", 5)]]
    (when,) = gone
    assert T0 + UDP_PEER_TIMEOUT_S < when <= T0 + UDP_PEER_TIMEOUT_S + 1.0
    snap = ch.snapshot()
    assert (snap["peers"], snap["peers_forgotten"]) == (0, 1)
    assert snap["packets_in"] == 1, "the counters of a forgotten peer are kept"


def test_a_peer_that_keeps_talking_stays_while_a_silent_one_goes():
    clock = Clock()
    ch, _sent = make_channel(clock)
    talker, quiet = ("10.0.0.1", 5), ("10.0.0.2", 6)
    datagram(ch, talker, HEARTBEAT, T0)
    datagram(ch, quiet, HEARTBEAT, T0)
    t = T0
    gone = []
    while t < T0 + 120.0:
        t += 0.5
        if t % 1.0 == 0:
            datagram(ch, talker, HEARTBEAT, t)
        gone += ch.sweep(t)
    assert gone == [quiet]
    assert list(ch.peers) == [talker]


@pytest.mark.parametrize("noise", [GARBAGE, RADIO_STATUS], ids=["garbage", "radio_status"])
def test_only_good_frames_keep_a_peer_alive(noise):
    """Garbage and a radio's own RADIO_STATUS say nothing about the ground station behind it."""
    clock = Clock()
    ch, _sent = make_channel(clock)
    addr = ("10.0.0.1", 5)
    datagram(ch, addr, HEARTBEAT, T0)
    t = T0
    gone = []
    while t < T0 + 31.5:
        t += 0.5
        datagram(ch, addr, noise, t)
        gone += ch.sweep(t)
    assert gone == [addr]


def test_a_forgotten_peer_is_admitted_again_by_its_next_good_frame():
    clock = Clock()
    ch, _sent = make_channel(clock)
    addr = ("10.0.0.1", 5)
    datagram(ch, addr, HEARTBEAT, T0)
    assert sweep_until(ch, T0, T0 + 32.0)
    datagram(ch, addr, HEARTBEAT, T0 + 33.0)
    assert ch.snapshot()["peers"] == 1
    assert ch.snapshot()["peers_forgotten"] == 1


def test_sweep_checks_at_most_once_a_second():
    clock = Clock()
    ch, _sent = make_channel(clock)
    datagram(ch, ("10.0.0.1", 5), HEARTBEAT, T0)
    assert ch.sweep(T0 + 29.9) == []  # checked: silent for less than 30 s
    assert ch.sweep(T0 + 30.5) == []  # 0.6 s after the last check: not checked
    assert ch.sweep(T0 + 30.95) == [("10.0.0.1", 5)]


def test_two_channels_sweep_independently():
    clock = Clock()
    busy, _ = make_channel(clock)
    idle, _ = make_channel(clock)
    datagram(busy, ("10.0.0.1", 5), HEARTBEAT, T0)
    datagram(idle, ("10.0.0.2", 6), HEARTBEAT, T0)
    t, gone = T0, []
    while t < T0 + 40.0:
        t += 0.01
        datagram(busy, ("10.0.0.1", 5), HEARTBEAT, t)
        busy.sweep(t)  # a busy channel sweeping all the time does not use up the other's turn
        if round(t * 100) % 100 == 0:
            gone += idle.sweep(t)
    assert gone == [("10.0.0.2", 6)]


@pytest.mark.parametrize("kind", ["tcp-server", "udp-client"])
def test_only_a_udp_server_forgets_silent_peers(kind):
    clock = Clock()
    conf = {"channels": [{"name": "x", "type": kind, "address": "127.0.0.1:14550"}]}
    ch = Channel(0, parse_config(yaml.safe_dump(conf), "t.yaml").channels[0], clock)
    ch.add_peer("remote", lambda data: True, T0)
    assert sweep_until(ch, T0, T0 + 60.0) == {}
    assert ch.snapshot()["peers"] == 1


# --- output version per peer ----------------------------------------------------------------

def test_each_peer_gets_its_own_version_and_a_mavlink2_peer_never_goes_back():
    clock = Clock()
    ch, sent = make_channel(clock)
    old, new = ("10.0.0.1", 1), ("10.0.0.2", 2)
    datagram(ch, old, HEARTBEAT_V1, T0)
    datagram(ch, new, HEARTBEAT, T0)
    datagram(ch, new, HEARTBEAT_V1, T0 + 0.1)  # a MAVLink1 frame from a MAVLink2 station
    msg = M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0, 3)
    assert ch.send_message(msg, 1, 1)
    assert [d[0] for d in sent[old]] == [0xFE]
    assert [d[0] for d in sent[new]] == [0xFD]
    datagram(ch, old, HEARTBEAT, T0 + 0.2)  # the MAVLink1 station upgrades
    assert ch.send_message(msg, 1, 1)
    assert [d[0] for d in sent[old]] == [0xFE, 0xFD]


# --- replies under the budget (outbox.py) ------------------------------------------------------

def _param_value(i: int):
    return M.MAVLink_param_value_message(f"P{i:04d}".encode(), float(i), M.MAV_PARAM_TYPE_REAL32, 1000, i)


def test_a_reply_finds_the_budget_spent_is_queued_not_dropped_and_goes_out_when_it_refills():
    clock = Clock()
    ch, sent = make_channel(clock, bandwidth=1000)  # 100 ms of budget: 100 bytes, i.e. one maximal frame
    addr = ("10.0.0.1", 5)
    ch.add_peer(addr, lambda data: sent.setdefault(addr, []).append(data) or True)
    ch.tick(clock.t, 0.0)
    while ch.write(HEARTBEAT):  # forwarded frames spend the budget (and the last one is a counted drop)
        pass
    drops = ch.stats.drops
    out = ch.out
    assert out.reply(_param_value(1), 1, 1) and out.reply(_param_value(2), 1, 1)
    assert len(out.replies) == 2 and ch.stats.drops == drops, "queued, not dropped"
    written = len(sent[addr])
    assert not out.flush_replies() and len(sent[addr]) == written, "still no room"
    clock.t += out.budget_wait_s(MAX_FRAME_BYTES)
    ch.tick(clock.t, 0.0)
    assert not out.flush_replies()  # room for one maximal frame: the first reply only
    clock.t += out.budget_wait_s(MAX_FRAME_BYTES)
    ch.tick(clock.t, 0.0)
    assert out.flush_replies() and not out.replies
    got = [m for m in (M.MAVLink(None).parse_buffer(b"".join(sent[addr][written:])) or [])]
    assert [m.param_index for m in got] == [1, 2], "in order, each once"
    assert ch.snapshot()["replies_dropped"] == 0


def test_the_reply_queue_is_bounded_and_counts_what_it_drops():
    from gcsd.links.outbox import REPLY_QUEUE_MAX

    clock = Clock()
    ch, _sent = make_channel(clock, bandwidth=1000)
    ch.add_peer(("10.0.0.1", 5), lambda data: True)
    ch.tick(clock.t, 0.0)
    while ch.write(HEARTBEAT):
        pass
    for i in range(REPLY_QUEUE_MAX + 3):
        ch.out.reply(_param_value(i), 1, 1)
    assert len(ch.out.replies) == REPLY_QUEUE_MAX and ch.snapshot()["replies_dropped"] == 3
    assert ch.out.replies[0][0].param_index == 3, "the oldest went first"


def test_without_a_budget_a_reply_goes_out_at_once():
    clock = Clock()
    ch, sent = make_channel(clock)
    addr = ("10.0.0.1", 5)
    ch.add_peer(addr, lambda data: sent.setdefault(addr, []).append(data) or True)
    assert ch.out.reply(_param_value(7), 1, 1) and not ch.out.replies and len(sent[addr]) == 1
