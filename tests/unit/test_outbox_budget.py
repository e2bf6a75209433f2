"""The byte budget is a budget whatever the loop's timing (outbox.py): a wake-up that comes seconds
late refills one bucket, not the seconds missed, and forwarded frames, our own messages and the
queued replies all draw on it, so at every wake-up the bytes sent since the start are at most
one bucket plus the rate times the time elapsed. A float `now`; no sockets, no loop."""

from __future__ import annotations

import random

import yaml
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.config import parse_config
from gcsd.links.channel import MAX_FRAME_BYTES, Channel

T0 = 1000.0
RATE_BPS = 960  # a 9600-baud radio
ADDR = ("10.0.0.1", 5)
HEARTBEAT = bytes(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3).pack(
    M.MAVLink(None, srcSystem=255, srcComponent=190)))


def _channel(now: list[float]) -> tuple[Channel, list[bytes]]:
    conf = {"channels": [{"name": "radio", "type": "udp-server", "address": "127.0.0.1:0", "bandwidth": RATE_BPS}]}
    ch = Channel(0, parse_config(yaml.safe_dump(conf), "t.yaml").channels[0], lambda: now[0])
    sent: list[bytes] = []
    ch.make_writer = lambda key: lambda data: sent.append(data) or True
    ch.tick(now[0], 0.0)
    ch.receive(ch.stranger(ADDR, now[0]), HEARTBEAT, now[0], datagram=True)  # a ground station: a peer
    return ch, sent


def _offer_everything(ch: Channel) -> None:
    """What a busy pass offers: forwarded frames, our telemetry while there is room, replies."""
    for _ in range(20):
        ch.write(HEARTBEAT)
    while ch.has_room():
        ch.send_message(M.MAVLink_attitude_message(1, 0.1, 0.2, 0.3, 0, 0, 0), 1, 1)
    for seq in range(10):
        ch.out.reply(M.MAVLink_param_value_message(b"SR0_EXTRA1", seq, M.MAV_PARAM_TYPE_INT16, 1000, seq), 1, 1)
    ch.out.flush_replies()


def test_a_wake_up_seconds_late_sends_one_bucket_not_the_seconds_missed():
    now = [T0]
    ch, sent = _channel(now)
    _offer_everything(ch)
    first = sum(map(len, sent))
    assert 0 < first <= MAX_FRAME_BYTES  # the full bucket at start: one maximal frame at 960 B/s
    now[0] = T0 + 5.0  # the loop was stalled for five seconds
    ch.tick(now[0], 0.0)
    _offer_everything(ch)
    assert sum(map(len, sent)) - first <= MAX_FRAME_BYTES
    assert ch.out.replies, "replies wait for the budget: queued, not sent past it"
    assert ch.snapshot()["drops"] > 0  # forwarded frames beyond it are dropped and counted


def test_sent_bytes_stay_within_one_bucket_plus_the_rate_however_the_wake_ups_come():
    rng = random.Random(20261126)
    now = [T0]
    ch, sent = _channel(now)
    for _ in range(2000):
        now[0] += rng.choice((0.0, 0.001, 0.02, 0.3, 2.5)) * rng.random()  # late, early, bunched
        ch.tick(now[0], 0.0)
        _offer_everything(ch)
        assert sum(map(len, sent)) <= MAX_FRAME_BYTES + RATE_BPS * (now[0] - T0)
    before, start = sum(map(len, sent)), now[0]
    for _ in range(1000):  # the control: a second of punctual wake-ups uses the whole rate
        now[0] += 0.001
        ch.tick(now[0], 0.0)
        _offer_everything(ch)
    assert 0.9 * RATE_BPS <= sum(map(len, sent)) - before <= MAX_FRAME_BYTES + RATE_BPS * (now[0] - start)
