"""Framing on top of pymavlink: raw bytes kept, unknown ids kept, resync after a false start.
Every test runs against both FrameParser.feed implementations: Python and the compiled one
(gcsd.wire.speedups; tests/unit/test_speedups.py compares them on random streams)."""

from __future__ import annotations

import random
import struct

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.wire import codec, speedups
from gcsd.wire.codec import Encoder, FrameParser


@pytest.fixture(autouse=True, params=["python", "c"])
def implementation(request, monkeypatch):
    if request.param == "c":
        if speedups.compiled is None:
            pytest.skip("gcsd.wire._speedups is not built (test_speedups fails for that in CI)")
        monkeypatch.setattr(codec, "_feed", speedups.compiled.feed)
    else:
        monkeypatch.setattr(codec, "_feed", codec.feed_python)
    return request.param


def frame(msg=None, sysid=255, compid=190, v1=False) -> bytes:
    msg = msg or M.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    return Encoder(sysid, compid).encode(msg, mavlink1=v1)


def unknown_frame(msgid=42424, payload=b"\x01\x02\x03") -> bytes:
    header = struct.pack("<BBBBBBBHB", 0xFD, len(payload), 0, 0, 0, 7, 9, msgid & 0xFFFF, msgid >> 16)  # seq 0, 7/9
    return header + payload + b"\x00\x00"  # CRC cannot be checked without the id's CRC_EXTRA


def test_good_frame_keeps_its_exact_bytes_and_targets():
    raw = frame()
    [f] = FrameParser().feed(raw)
    assert f.raw == raw
    assert (f.sysid, f.compid, f.msgid, f.version) == (255, 190, 76, 2)
    assert (f.target_system, f.target_component) == (1, 1)


def test_message_without_target_fields_has_minus_one_targets():
    [f] = FrameParser().feed(frame(M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)))
    assert (f.target_system, f.target_component) == (-1, -1)


def test_mavlink1_frame_is_version_1():
    [f] = FrameParser().feed(frame(v1=True))
    assert f.version == 1 and f.raw[0] == 0xFE


def test_unknown_message_id_is_kept_raw_for_forwarding():
    p = FrameParser()
    [f] = p.feed(unknown_frame())
    assert f.msg is None and f.msgid == 42424 and (f.sysid, f.compid) == (7, 9)
    assert f.raw == unknown_frame()
    assert p.stats.unknown_ids == 1


def test_bad_crc_is_counted_and_dropped():
    raw = bytearray(frame())
    raw[-1] ^= 0xFF
    p = FrameParser()
    assert p.feed(bytes(raw)) == []
    assert p.stats.crc_errors == 1


def test_frame_hidden_behind_a_false_start_is_found():
    # a stray STX with a plausible length swallows the real frame in a naive parser
    garbage = bytes([0xFD, 20, 0, 0, 0, 1, 1, 0, 0, 0])
    good = frame()
    p = FrameParser()
    frames = p.feed(garbage + good + b"\x00" * 40)
    assert [f.raw for f in frames] == [good]


def test_garbage_between_frames_is_counted_and_frames_survive():
    rng = random.Random(7)
    good = frame()
    noise = bytes(rng.randrange(256) for _ in range(500)).replace(b"\xfd", b"\x00").replace(b"\xfe", b"\x00")
    p = FrameParser()
    frames = p.feed(noise + good + noise + good)
    assert len(frames) == 2
    assert p.stats.parse_errors >= 2


def test_stream_split_at_every_byte_still_parses():
    good = frame() + frame(M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
    p = FrameParser()
    frames = []
    for i in range(len(good)):
        frames += p.feed(good[i:i + 1])
    assert len(frames) == 2


def test_sequence_gaps_are_counted_per_source():
    enc = Encoder(255, 190)
    msg = M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)
    frames = [enc.encode(msg) for _ in range(10)]
    p = FrameParser()
    p.feed(b"".join(frames[:3] + frames[6:]))  # 3 lost
    assert p.stats.seq_gaps == 3


def test_reset_drops_a_truncated_frame():
    p = FrameParser()
    p.feed(frame()[:-3])
    assert p.pending_bytes() > 0
    p.reset()
    assert p.pending_bytes() == 0 and p.stats.parse_errors == 1


def test_mavlink1_encoder_refuses_ids_above_255():
    msg = M.MAVLink_button_change_message(0, 0, 1)  # id 257
    assert Encoder(1, 1).encode(msg, mavlink1=True) is None
    assert Encoder(1, 1).encode(msg)[0] == 0xFD


def test_encoder_sequence_wraps():
    enc = Encoder(1, 1)
    msg = M.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3)
    seqs = [enc.encode(msg)[4] for _ in range(258)]
    assert seqs[255] == 255 and seqs[256] == 0
