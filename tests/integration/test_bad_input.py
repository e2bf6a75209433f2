"""Bad input (SPEC.md "Bad input"): garbage, truncated frames, wrong CRCs and oversized length
fields on one channel. The daemon keeps running, keeps serving other channels at their configured
rates, counts what it dropped, and still answers on the channel that was flooded.
"""

from __future__ import annotations

import random
import time

import pytest

from .helpers import (
    VEHICLE,
    Client,
    M,
    from_vehicle,
    is_ack,
    measure_rates,
    packed,
    pump,
    rate_hz,
    tcp_channel,
    tcp_url,
    udp_channel,
    udp_url,
    wait_for,
)

SEED = 0x6CD5
B_ATTITUDE_HZ = 10
FLOOD_S = 2.0
FLOOD_BYTES_PER_S = 50_000
NOISE_SOURCE = (77, 1)
STX = (0xFD, 0xFE)


def _command_frame(command: int = M.MAV_CMD_GET_MESSAGE_INTERVAL, src=NOISE_SOURCE) -> bytes:
    msg = M.MAVLink_command_long_message(*VEHICLE, command, 0, M.MAVLINK_MSG_ID_ATTITUDE, 0, 0, 0, 0, 0, 0)
    return packed(msg, *src)


def bad_crc(frame: bytes) -> bytes:
    return frame[:-2] + bytes([frame[-2] ^ 0x5A, frame[-1] ^ 0xA5])


def truncated(frame: bytes) -> bytes:
    return frame[: len(frame) // 2]


def oversized_length(payload_bytes: int = 20) -> bytes:
    """A MAVLink2 header that claims 255 payload bytes, followed by far fewer."""
    return bytes([0xFD, 255, 0, 0, 0, *NOISE_SOURCE, 0, 0, 0]) + bytes(payload_bytes)


def no_stx(rng: random.Random, n: int) -> bytes:
    """Random bytes that contain no start-of-frame marker."""
    return bytes(b if b not in STX else 0x55 for b in rng.randbytes(n))


def junk(rng: random.Random) -> bytes:
    """One piece of bad input: random bytes, a frame with a bad CRC, a truncated or oversized frame."""
    kind = rng.randrange(4)
    if kind == 0:
        return rng.randbytes(rng.randint(1, 280))
    if kind == 1:
        return bad_crc(_command_frame())
    if kind == 2:
        return truncated(_command_frame())
    return oversized_length(rng.randint(0, 40))


def _daemon(daemon, client, kind: str):
    a_channel = udp_channel("a") if kind == "udp" else tcp_channel("a")
    d = daemon({"channels": [a_channel, udp_channel("b", streams={"extra1": B_ATTITUDE_HZ})]})
    a = client((udp_url if kind == "udp" else tcp_url)(d.port("a")), 255, 190)
    b = client(udp_url(d.port("b")), 254, 190)
    for c in (a, b):
        c.heartbeat()
        assert wait_for(c, from_vehicle, others=[a, b]), "nothing from the vehicle"
    return d, a, b


def ask_until_answered(a: Client, others, timeout: float = 10.0) -> bool:
    """A ground station repeats a command until it is acknowledged, as real ones do."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        mark = a.mark()
        a.command_long(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)
        if wait_for(a, is_ack(M.MAV_CMD_GET_MESSAGE_INTERVAL), timeout=0.5, since=mark, others=others):
            return True
    return False


@pytest.mark.parametrize("kind", ["udp", "tcp"])
def test_flood_of_bad_input_on_one_channel_does_not_slow_another(daemon, client, kind):
    d, a, b = _daemon(daemon, client, kind)
    before = measure_rates({"b": b}, {"b": ("ATTITUDE",)}, 1.2)[("b", "ATTITUDE")]

    rng = random.Random(SEED)
    mark = b.mark()
    start = time.monotonic()
    sent = 0
    while time.monotonic() - start < FLOOD_S:
        piece = junk(rng)
        a.write(piece)
        sent += len(piece)
        pause = start + sent / FLOOD_BYTES_PER_S - time.monotonic()
        if pause > 0:
            pump([a, b], pause)
    during = rate_hz([r for r in b.since(mark, "ATTITUDE") if r.src == VEHICLE])

    assert abs(before - B_ATTITUDE_HZ) <= 0.1 * B_ATTITUDE_HZ, before
    assert abs(during - B_ATTITUDE_HZ) <= 0.1 * B_ATTITUDE_HZ, f"{during:.2f} Hz during the flood"
    assert [r for r in b.received if r.src == NOISE_SOURCE] == []  # bad frames are not forwarded
    assert ask_until_answered(a, [b]), "the flooded channel no longer answers"
    stats = d.stats("a")
    assert stats["parse_errors"] > 0, stats
    assert stats["crc_errors"] > 0, stats
    assert d.stats("b")["parse_errors"] == 0


@pytest.mark.parametrize(
    ("what", "data", "counter"),
    [
        ("random bytes", random.Random(SEED).randbytes(300), "parse_errors"),
        ("a wrong CRC", bad_crc(_command_frame()), "crc_errors"),
        ("a truncated frame", truncated(_command_frame()), "parse_errors"),
        ("an oversized length field", oversized_length(), "parse_errors"),
    ],
    ids=["random", "bad_crc", "truncated", "oversized_length"],
)
def test_each_kind_of_bad_datagram_is_counted_and_not_processed(daemon, client, what, data, counter):
    d, a, b = _daemon(daemon, client, "udp")
    mark = a.mark()
    a.write(data)
    # the control, just after on the same socket: a good command is answered, so the bad one was read
    a.command_long(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)
    assert wait_for(a, is_ack(M.MAV_CMD_GET_MESSAGE_INTERVAL), since=mark, others=[b]), what
    b.read_available()  # a wrong copy to b would have been written before that ACK
    assert d.stats("a")[counter] > 0, what
    assert len([r for r in a.since(mark, "COMMAND_ACK") if r.src == VEHICLE]) == 1, what
    assert [r for r in b.received if r.src == NOISE_SOURCE] == [], what


def test_frame_right_after_garbage_in_the_same_tcp_write_is_parsed(daemon, client):
    d, a, b = _daemon(daemon, client, "tcp")
    mark = a.mark()
    a.write(no_stx(random.Random(SEED), 500) + _command_frame(src=(255, 190)))
    ack = wait_for(a, is_ack(M.MAV_CMD_GET_MESSAGE_INTERVAL), since=mark, others=[b])
    assert ack is not None and ack.msg.result == M.MAV_RESULT_ACCEPTED
    assert d.stats("a")["parse_errors"] > 0


def test_frame_hidden_behind_a_false_start_is_found_when_the_stream_goes_on(daemon, client):
    # 0xFD claiming 255 payload bytes of a HEARTBEAT swallows the real command that follows; when
    # enough bytes have arrived the false frame fails its CRC and the parser rescans after it.
    d, a, b = _daemon(daemon, client, "tcp")
    mark = a.mark()
    a.write(bytes([0xFD, 255, 0, 0, 0, *NOISE_SOURCE, 0, 0, 0]) + no_stx(random.Random(SEED), 30)
            + _command_frame(src=(255, 190)))
    ack = None
    deadline = time.monotonic() + 20.0  # about ten heartbeats bring the 255 bytes; the rest is slack for load
    while ack is None and time.monotonic() < deadline:  # the station goes on heartbeating, as it always does
        a.heartbeat()
        ack = wait_for(a, is_ack(M.MAV_CMD_GET_MESSAGE_INTERVAL), timeout=0.1, since=mark, others=[b])
    assert ack is not None and ack.msg.result == M.MAV_RESULT_ACCEPTED
    assert d.stats("a")["crc_errors"] > 0


def test_garbage_does_not_keep_new_nodes_from_being_routed(daemon, client):
    d = daemon({"channels": [udp_channel("noisy"), udp_channel("gcs"), udp_channel("cam")]})
    noisy = client(udp_url(d.port("noisy")), 200, 1)
    gcs = client(udp_url(d.port("gcs")), 255, 190)
    gcs.heartbeat()
    assert wait_for(gcs, from_vehicle)
    rng = random.Random(SEED)
    for _ in range(400):  # 100 kB of random bytes, in datagrams, as from a noisy radio
        noisy.write(rng.randbytes(250))
    pump([noisy, gcs], 0.5)

    cam = client(udp_url(d.port("cam")), 1, 100)  # a camera appears after the noise
    cam.heartbeat(M.MAV_TYPE_CAMERA)
    assert wait_for(cam, from_vehicle, others=[gcs, noisy])
    raw = gcs.command_long(M.MAV_CMD_IMAGE_START_CAPTURE, target=(1, 100))
    assert wait_for(cam, lambda r: r.raw == raw, others=[noisy, gcs]), "the command for the camera never reached it"
