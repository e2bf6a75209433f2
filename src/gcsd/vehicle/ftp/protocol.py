"""MAVLink FTP payloads, opcodes and NAK codes, as data (REFERENCE.md section 8).

The FILE_TRANSFER_PROTOCOL payload is 251 bytes, little-endian:

    [0..1] u16 seq   [2] session   [3] opcode   [4] size   [5] req_opcode
    [6] burst_complete   [7] padding   [8..11] u32 offset   [12..250] data (239 bytes)

`Payload.unpack` never fails: a short payload is zero-extended (MAVLink2 trims trailing zeros).
`Payload.pack` always gives the full 251 bytes, data zero-padded, so nothing stale leaks.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass, replace

PAYLOAD_BYTES = 251
HEADER_BYTES = 12
DATA_MAX = PAYLOAD_BYTES - HEADER_BYTES  # 239
SEQ_MODULO = 1 << 16

_HEADER = struct.Struct("<HBBBBBxI")


class Op(enum.IntEnum):
    NONE = 0
    TERMINATE_SESSION = 1
    RESET_SESSIONS = 2
    LIST_DIRECTORY = 3
    OPEN_FILE_RO = 4
    READ_FILE = 5
    CREATE_FILE = 6
    WRITE_FILE = 7
    REMOVE_FILE = 8
    CREATE_DIRECTORY = 9
    REMOVE_DIRECTORY = 10
    OPEN_FILE_WO = 11
    TRUNCATE_FILE = 12
    RENAME = 13
    CALC_FILE_CRC32 = 14
    BURST_READ_FILE = 15
    ACK = 128
    NAK = 129


class Nak(enum.IntEnum):
    NONE = 0
    FAIL = 1
    FAIL_ERRNO = 2
    INVALID_DATA_SIZE = 3
    INVALID_SESSION = 4
    NO_SESSIONS_AVAILABLE = 5
    EOF = 6
    UNKNOWN_COMMAND = 7
    FILE_EXISTS = 8
    FILE_PROTECTED = 9
    FILE_NOT_FOUND = 10


@dataclass(frozen=True, slots=True)
class Payload:
    seq: int = 0
    session: int = 0
    opcode: int = 0
    size: int = 0
    req_opcode: int = 0
    burst_complete: int = 0
    offset: int = 0
    data: bytes = b""

    def __repr__(self) -> str:
        op = Op(self.opcode).name if self.opcode in Op._value2member_map_ else str(self.opcode)
        req = Op(self.req_opcode).name if self.req_opcode in Op._value2member_map_ else str(self.req_opcode)
        return (f"Payload(seq={self.seq}, session={self.session}, {op}, size={self.size}, req={req}, "
                f"bc={self.burst_complete}, offset={self.offset}, data={self.data[:self.size]!r})")

    @classmethod
    def unpack(cls, raw: bytes | bytearray | list[int]) -> Payload:
        raw = bytes(raw)
        if len(raw) < PAYLOAD_BYTES:
            raw = raw + bytes(PAYLOAD_BYTES - len(raw))
        seq, session, opcode, size, req_opcode, burst_complete, offset = _HEADER.unpack_from(raw)
        data = raw[HEADER_BYTES:PAYLOAD_BYTES]
        return cls(seq, session, opcode, size, req_opcode, burst_complete, offset, data)

    def pack(self) -> bytes:
        data = self.data[:DATA_MAX]
        return (
            _HEADER.pack(self.seq & 0xFFFF, self.session, self.opcode, self.size, self.req_opcode,
                         self.burst_complete, self.offset & 0xFFFFFFFF)
            + data + bytes(DATA_MAX - len(data))
        )

    def reply(self, opcode: int, size: int = 0, data: bytes = b"", offset: int | None = None,
              burst_complete: int = 0, seq_step: int = 1) -> Payload:
        """A reply to this request: seq + step (wrapping at 65536), same session, req_opcode set."""
        return replace(
            self, seq=(self.seq + seq_step) % SEQ_MODULO, opcode=opcode, size=size, req_opcode=self.opcode,
            burst_complete=burst_complete, offset=self.offset if offset is None else offset, data=data,
        )

    def ack(self, data: bytes = b"", offset: int | None = None, burst_complete: int = 0,
            seq_step: int = 1) -> Payload:
        return self.reply(Op.ACK, len(data), data, offset, burst_complete, seq_step)

    def nak(self, code: int, errno_value: int = 0, offset: int | None = None, burst_complete: int = 0,
            seq_step: int = 1) -> Payload:
        """A NAK; FailErrno carries the errno as a second byte (size 2), every other code size 1."""
        data = bytes([code, errno_value & 0xFF]) if code == Nak.FAIL_ERRNO else bytes([code])
        return self.reply(Op.NAK, len(data), data, offset, burst_complete, seq_step)


class FtpError(Exception):
    """An operation failed with a protocol answer: a NAK code (and an errno for FailErrno)."""

    def __init__(self, code: Nak, errno_value: int = 0) -> None:
        super().__init__(f"{code.name}" + (f" errno {errno_value}" if errno_value else ""))
        self.code = code
        self.errno_value = errno_value


def crc32_ardupilot(data: bytes | memoryview, crc: int = 0) -> int:
    """ArduPilot's crc_crc32: reflected CRC-32 (0xEDB88320), seed 0, no final XOR.

    zlib.crc32 inverts on entry and exit; seeding with ~crc and inverting the result cancels both.
    """
    import zlib

    return (zlib.crc32(data, crc ^ 0xFFFFFFFF) ^ 0xFFFFFFFF) & 0xFFFFFFFF


def path_arg(req: Payload) -> bytes:
    """The path of a request, checked as ArduPilot's check_name_len does.

    size must be > 0 and equal the string length, or the length + 1 (a trailing NUL);
    anything else is InvalidDataSize.
    """
    size = req.size
    data = req.data[:DATA_MAX]
    if size == 0 or size > DATA_MAX:
        raise FtpError(Nak.INVALID_DATA_SIZE)
    nul = data.find(b"\0")
    length = nul if nul >= 0 else len(data)
    if length == size or (size - length == 1 and nul == length):
        return data[:length]
    raise FtpError(Nak.INVALID_DATA_SIZE)


def two_path_args(req: Payload) -> tuple[bytes, bytes]:
    """Rename's "old\\0new": size = both lengths + 1, or + 2 with a trailing NUL."""
    size = req.size
    data = req.data[:DATA_MAX]
    first_end = data.find(b"\0")
    if size == 0 or size > DATA_MAX or first_end <= 0:
        raise FtpError(Nak.INVALID_DATA_SIZE)
    second_end = data.find(b"\0", first_end + 1)
    if second_end < 0:
        second_end = len(data)
    len1, len2 = first_end, second_end - first_end - 1
    if len2 <= 0 or size not in (len1 + len2 + 1, len1 + len2 + 2):
        raise FtpError(Nak.INVALID_DATA_SIZE)
    return data[:first_end], data[first_end + 1:second_end]
