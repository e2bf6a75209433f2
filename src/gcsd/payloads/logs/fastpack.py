"""LOG_DATA packed without pymavlink's per-byte work: the hot message of a log download.

pymavlink packs LOG_DATA's 90-byte array as 90 separate struct arguments and computes the CRC
in Python; at the 35 000 messages a second a fast download needs that is a fifth of the cost.
`LogData` is a pymavlink LOG_DATA message (it decodes, compares and prints as one) whose `pack`
builds an unsigned MAVLink2 frame directly: the header, the payload with its trailing zeros
trimmed (as pymavlink does, never below one byte) and the CRC from codec's fast X.25. A signed
frame or a MAVLink1 frame is left to pymavlink. The bytes are identical either way (unit test).
"""

from __future__ import annotations

import struct

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.wire.codec import crc16

_PAYLOAD = struct.Struct("<IHB90s")
_HEADER = struct.Struct("<BBBBBBBHB")
_CRC = struct.Struct("<H")
_EXTRA = bytes((M.MAVLink_log_data_message.crc_extra,))
_MSGID = M.MAVLINK_MSG_ID_LOG_DATA


class LogData(M.MAVLink_log_data_message):
    def __init__(self, id: int, ofs: int, count: int, data: bytes) -> None:
        super().__init__(id, ofs, count, data)

    def pack(self, mav, force_mavlink1: bool = False) -> bytes:
        if force_mavlink1 or mav.signing.sign_outgoing:
            self.data = bytes(self.data).ljust(90, b"\0")
            return super().pack(mav, force_mavlink1=force_mavlink1)
        payload = _PAYLOAD.pack(self.ofs, self.id, self.count, self.data).rstrip(b"\0") or b"\0"
        header = _HEADER.pack(0xFD, len(payload), 0, 0, mav.seq, mav.srcSystem, mav.srcComponent,
                              _MSGID & 0xFFFF, _MSGID >> 16)
        body = header + payload
        return body + _CRC.pack(crc16(body[1:] + _EXTRA))
