"""MAVLink framing and encoding, on top of pymavlink.

Receive: `FrameParser.feed(data)` turns a byte stream into `Frame`s. pymavlink's parser does the
framing, CRC (with fastcrc) and decoding; this module adds what a router needs:

- the raw bytes of every good frame (forwarding is byte-exact, signature included),
- frames with a message id the dialect does not know, kept raw (`msg is None`) so the router can
  forward them as broadcasts, as the MAVLink routing guide asks,
- counters: parse errors (bytes that are not a frame), CRC errors, sequence gaps per source,
- a resync strategy for noisy serial: a frame that fails its CRC is not swallowed whole; the
  parser restarts on the byte after its false start, so a real frame hidden behind a stray
  0xFD/0xFE is still found.

Send: `Encoder` packs messages for one (channel, source component) pair: its own sequence
number, MAVLink1 or MAVLink2 output, and (later) signing. MAVLink1 cannot carry ids > 255;
such messages are not sent on a MAVLink1 link, as in ArduPilot.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as mavlink

MAVLink_message = mavlink.MAVLink_message
STX_V1 = 0xFE
STX_V2 = 0xFD
MSG_ID_RADIO_STATUS = mavlink.MAVLINK_MSG_ID_RADIO_STATUS
MSG_ID_RADIO = mavlink.MAVLINK_MSG_ID_RADIO
_CRC_ERROR = "invalid MAVLink CRC"


@dataclass(slots=True)
class Frame:
    """One good frame as received: the decoded message (None for unknown ids) and its bytes."""

    raw: bytes
    msg: MAVLink_message | None
    msgid: int
    sysid: int
    compid: int
    seq: int
    version: int
    target_system: int = -1  # -1: the message has no target field
    target_component: int = -1

    @property
    def name(self) -> str:
        return self.msg.get_type() if self.msg is not None else f"UNKNOWN_{self.msgid}"


@dataclass
class ParseStats:
    """What a parser saw; owned by the parser, summed into the channel's counters."""

    frames: int = 0
    bytes: int = 0
    parse_errors: int = 0
    crc_errors: int = 0
    unknown_ids: int = 0
    seq_gaps: int = 0
    last_seq: dict[tuple[int, int], int] = field(default_factory=dict)


def _header_fields(raw: bytes | bytearray) -> tuple[int, int, int, int, int]:
    """(version, seq, sysid, compid, msgid) straight from a frame's header bytes."""
    if raw[0] == STX_V2:
        return 2, raw[4], raw[5], raw[6], raw[7] | (raw[8] << 8) | (raw[9] << 16)
    return 1, raw[2], raw[3], raw[4], raw[5]


class FrameParser:
    """Stream of bytes in, frames out. One per peer (a UDP client, a TCP connection, a serial port)."""

    def __init__(self, stats: ParseStats | None = None, keep_bad_crc: bool = False) -> None:
        self.stats = stats if stats is not None else ParseStats()
        self._mav = mavlink.MAVLink(None)
        self._mav.robust_parsing = True
        self._keep_bad_crc = keep_bad_crc
        self.bad_crc_frames: list[bytes] = []  # frames that failed their CRC (forward_bad_crc); caller drains

    @property
    def signing(self):
        """pymavlink's signing state of this parser (secret_key, callbacks, counters)."""
        return self._mav.signing

    def feed(self, data: bytes) -> list[Frame]:
        stats = self.stats
        stats.bytes += len(data)
        frames: list[Frame] = []
        mav = self._mav
        m = mav.parse_char(data)
        while m is not None:
            self._take(m, frames)
            m = mav.parse_char(b"")
        return frames

    def pending_bytes(self) -> int:
        """Bytes held waiting for the rest of a frame (a truncated frame, if the stream ended)."""
        return len(self._mav.buf) - self._mav.buf_index

    def reset(self) -> int:
        """Drop a partial frame (end of a UDP datagram); returns how many bytes were dropped."""
        dropped = self.pending_bytes()
        if dropped:
            self.stats.parse_errors += 1
        self._mav.buf = bytearray()
        self._mav.buf_index = 0
        self._mav.expected_length = mavlink.HEADER_LEN_V1 + 2
        return dropped

    def _take(self, m: MAVLink_message, frames: list[Frame]) -> None:
        stats = self.stats
        kind = m.get_type()
        if kind == "BAD_DATA":
            reason = m.reason
            if reason.startswith(_CRC_ERROR):
                stats.crc_errors += 1
                if self._keep_bad_crc:
                    self.bad_crc_frames.append(bytes(m.data))
                self._rescan_after_false_start(m.data)
            else:
                stats.parse_errors += 1
            return
        raw = bytes(m.get_msgbuf())
        version, seq, sysid, compid, msgid = _header_fields(raw)
        if kind.startswith("UNKNOWN_"):
            stats.unknown_ids += 1
            frame = Frame(raw, None, msgid, sysid, compid, seq, version)
        else:
            frame = Frame(
                raw, m, msgid, sysid, compid, seq, version,
                getattr(m, "target_system", -1), getattr(m, "target_component", -1),
            )
        stats.frames += 1
        key = (sysid, compid)
        last = stats.last_seq.get(key)
        if last is not None:
            stats.seq_gaps += (seq - last - 1) & 0xFF
        if len(stats.last_seq) < 256 or last is not None:
            stats.last_seq[key] = seq
        frames.append(frame)

    def _rescan_after_false_start(self, bad: bytearray) -> None:
        """Put back everything after the false STX so a frame hidden inside is found."""
        mav = self._mav
        rest = bytes(bad[1:])
        start = next((i for i, b in enumerate(rest) if b in (STX_V1, STX_V2)), len(rest))
        if start < len(rest):
            mav.buf = bytearray(rest[start:]) + mav.buf[mav.buf_index:]
            mav.buf_index = 0
        if start:
            self.stats.parse_errors += 1


class Encoder:
    """Packs messages from one source (sysid, compid) onto one link; owns that link's sequence."""

    def __init__(self, sysid: int, compid: int) -> None:
        self._mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)

    @property
    def signing(self):
        return self._mav.signing

    def encode(self, msg: MAVLink_message, mavlink1: bool = False) -> bytes | None:
        if mavlink1 and msg.get_msgId() > 255:
            return None
        mav = self._mav
        raw = msg.pack(mav, force_mavlink1=mavlink1)
        mav.seq = (mav.seq + 1) & 0xFF
        return raw


def decode_targets(msg: MAVLink_message) -> tuple[int, int]:
    return getattr(msg, "target_system", -1), getattr(msg, "target_component", -1)


def message_class(msgid: int):
    """The pymavlink class for a message id, or None if the dialect does not know it."""
    return mavlink.mavlink_map.get(msgid)
