"""Benchmark traffic: pre-encoded MAVLink2 frames with a per-packet sequence number, and a header walker.

The test packet is COMMAND_LONG(target_system=250, target_component=1, command=MAV_CMD_USER_1,
param1=float(seq)) sent by sysid 200 / compid 190.  ``seq`` is an integer below 2**24 (exact as a
float32), unique within one benchmark run, so the receiver can detect loss, duplicates and
reordering exactly.

Encoding every packet with pymavlink costs ~20 us, too slow for a sender that must offer 100 k
packets/s.  The MAVLink CRC (CRC-16/MCRF4XX) is affine in the message bytes, so for frames of the same
length ``crc(base ^ delta) == crc(base) ^ crc0(delta)``, and ``crc0`` of a delta that touches only a
few byte positions is the XOR of one table entry per position.  ``FrameFactory`` builds the template
once with pymavlink, precomputes one 256-entry table for each varying byte (the header sequence
byte and the four bytes of param1) and then makes a frame in ~1.5 us.  ``check()`` decodes samples
with pymavlink to prove the frames are valid.

``walk_frames`` is the receiver's parser: it walks MAVLink1/2 headers in a datagram without
decoding payloads (pymavlink ``parse_buffer`` manages only ~100-180 k frames/s and would make the
receiver the bottleneck).
"""

from __future__ import annotations

import struct

from pymavlink.dialects.v20 import ardupilotmega as mavlink2
from pymavlink.generator.mavcrc import x25crc

SENDER_SYSID = 200
SENDER_COMPID = 190
TARGET_SYSID = 250
TARGET_COMPID = 1
MSGID_COMMAND_LONG = mavlink2.MAVLINK_MSG_ID_COMMAND_LONG
MSGID_HEARTBEAT = mavlink2.MAVLINK_MSG_ID_HEARTBEAT
MAX_SEQ = 1 << 24
_PARAM1_OFFSET = 10  # MAVLink2 header is 10 bytes; param1 is the first payload field
_HDR_SEQ_OFFSET = 4
_VARYING = (_HDR_SEQ_OFFSET, 10, 11, 12, 13)
_pack_f = struct.Struct("<f").pack
_unpack_f = struct.Struct("<f").unpack_from


def _crc(body: bytes, crc_extra: int) -> int:
    c = x25crc(body)
    c.accumulate(bytes([crc_extra]))
    return c.crc


class FrameFactory:
    """Makes COMMAND_LONG frames carrying ``seq``; see the module docstring."""

    def __init__(self) -> None:
        mav = mavlink2.MAVLink(None, srcSystem=SENDER_SYSID, srcComponent=SENDER_COMPID)
        mav.seq = 0
        msg = mav.command_long_encode(
            TARGET_SYSID, TARGET_COMPID, mavlink2.MAV_CMD_USER_1, 0, 0.0, 0, 0, 0, 0, 0, 0
        )
        frame = msg.pack(mav)
        extra = mavlink2.MAVLink_command_long_message.crc_extra
        self.template = bytearray(frame)
        body = bytes(frame[1:-2])
        self._base_crc = _crc(body, extra)
        assert self._base_crc == struct.unpack("<H", frame[-2:])[0]
        self._tables = []
        for pos in _VARYING:
            table = []
            for v in range(256):
                b = bytearray(body)
                b[pos - 1] = v
                table.append(_crc(bytes(b), extra) ^ self._base_crc)
            self._tables.append(table)
        self.length = len(frame)

    def frame(self, seq: int) -> bytes:
        t_hdr, t0, t1, t2, t3 = self._tables
        b = bytearray(self.template)
        p = _pack_f(float(seq))
        h = seq & 0xFF
        b[_HDR_SEQ_OFFSET] = h
        b[10:14] = p
        crc = self._base_crc ^ t_hdr[h] ^ t0[p[0]] ^ t1[p[1]] ^ t2[p[2]] ^ t3[p[3]]
        b[-2] = crc & 0xFF
        b[-1] = crc >> 8
        return bytes(b)

    def frames(self, start: int, count: int) -> list[bytes]:
        assert 0 <= start and start + count <= MAX_SEQ, "sequence numbers must stay below 2**24"
        f = self.frame
        return [f(s) for s in range(start, start + count)]

    def check(self, seqs=(0, 1, 255, 256, 65535, 123457, MAX_SEQ - 1)) -> None:
        """Decode sample frames with pymavlink (CRC checked) and compare the fields."""
        mav = mavlink2.MAVLink(None)
        for s in seqs:
            msgs = mav.parse_buffer(self.frame(s)) or []
            assert len(msgs) == 1, f"seq {s}: pymavlink decoded {msgs!r}"
            m = msgs[0]
            assert m.get_type() == "COMMAND_LONG", m
            assert int(m.param1) == s and m.target_system == TARGET_SYSID, m
            assert m.get_seq() == s & 0xFF and m.get_srcSystem() == SENDER_SYSID, m


def heartbeat(sysid: int, compid: int, mav_type: int, seq: int = 0) -> bytes:
    mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.seq = seq & 0xFF
    return mav.heartbeat_encode(mav_type, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3).pack(mav)


def walk_frames(data, n: int):
    """Yield (sysid, msgid, payload_offset) for each MAVLink frame in data[:n]; stops at garbage."""
    off = 0
    while off + 8 <= n:
        stx = data[off]
        if stx == 0xFD:
            plen = data[off + 1]
            yield data[off + 5], data[off + 7] | (data[off + 8] << 8) | (data[off + 9] << 16), off + 10
            off += 12 + plen + (13 if data[off + 2] & 1 else 0)
        elif stx == 0xFE:
            yield data[off + 3], data[off + 5], off + 6
            off += 8 + data[off + 1]
        else:
            yield None, None, off
            return


def seq_of(data, payload_offset: int) -> int:
    return int(_unpack_f(data, payload_offset)[0])


def received_frames(sock, buf: bytearray, timeout_s: float):
    """Yield (sysid, msgid, payload_offset, payload_len) for every MAVLink2 frame in the datagrams
    that arrive on `sock` within one wait (`buf` holds the current datagram while it is walked)."""
    import select
    import socket

    if not select.select([sock], [], [], timeout_s)[0]:
        return
    while True:
        try:
            n = sock.recv_into(buf, 0, socket.MSG_DONTWAIT)
        except (BlockingIOError, ConnectionRefusedError):
            return
        for sysid, msgid, off in walk_frames(buf, n):
            if sysid is None:
                break
            yield sysid, msgid, off, buf[off - 9]
