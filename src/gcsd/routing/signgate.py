"""The signing gateway (SPEC.md "Companion routing", `options: [sign_forwarded]`): a pure function.

A frame that arrives unsigned on a trusted local channel (serial, or bound to / pointed at a
loopback address: config_companion.py refuses the option elsewhere) is forwarded signed with
the daemon's key, link id = the ingress channel's index, a fresh timestamp, so that a local tool
can command a flight controller that requires signing. A MAVLink1 frame is re-framed as
MAVLink2 first (same sequence, source and payload). The incompatibility flag changes the
header, so the CRC is computed again (with the message's CRC_EXTRA); a frame whose message id
the dialect does not know cannot be re-checksummed and is forwarded as it came (None).
Frames from every other channel are never touched: an unsigned stranger on the LAN can never
obtain a signature (MAVProxy#1683).
"""

from __future__ import annotations

import struct

from gcsd.wire.codec import MESSAGE_INFO, STX_V1, STX_V2, crc16
from gcsd.wire.signing import signature_of

IFLAG_SIGNED = 0x01


def signed_copy(raw: bytes, key: bytes, link_id: int, timestamp: int) -> bytes | None:
    """`raw` (an unsigned MAVLink1 or 2 frame) as a signed MAVLink2 frame; None if it cannot be."""
    if raw[0] == STX_V2:
        if raw[2] & IFLAG_SIGNED:
            return None
        length = raw[1]
        seq, sysid, compid = raw[4], raw[5], raw[6]
        msgid = raw[7] | raw[8] << 8 | raw[9] << 16
        payload = raw[10:10 + length]
    elif raw[0] == STX_V1:
        length = raw[1]
        seq, sysid, compid, msgid = raw[2], raw[3], raw[4], raw[5]
        payload = raw[6:6 + length]
    else:
        return None
    info = MESSAGE_INFO.get(msgid)
    if info is None:
        return None
    header = bytes((STX_V2, len(payload), IFLAG_SIGNED, 0, seq, sysid, compid,
                    msgid & 0xFF, msgid >> 8 & 0xFF, msgid >> 16))
    body = header + payload
    frame = body + struct.pack("<H", crc16(body[1:] + bytes((info.crc_extra,))))
    frame += bytes((link_id & 0xFF,)) + timestamp.to_bytes(6, "little")
    return frame + signature_of(key, frame)
