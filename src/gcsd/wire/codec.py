"""MAVLink framing and encoding, on top of pymavlink.

Receive: `FrameParser.feed(data)` turns a byte stream into `Frame`s. Like mavlink-router, the
routing header is parsed once per frame and nothing more: framing, the CRC (fastcrc, with the
dialect's CRC_EXTRA from pymavlink) and the target fields read at their payload offsets.
pymavlink decodes a frame only when something local reads `Frame.msg`. What a router needs:

- the raw bytes of every good frame (forwarding is byte-exact, signature included),
- frames with a message id the dialect does not know, kept raw (`known = False`) so the router
  can forward them as broadcasts, as the MAVLink routing guide asks,
- counters: parse errors (bytes that are not a frame), CRC errors, sequence gaps per source,
- a resync strategy for noisy serial: a frame that fails its CRC is not swallowed whole; the
  parser restarts on the byte after its false start, so a real frame hidden behind a stray
  0xFD/0xFE is still found.

Send: `Encoder` packs messages for one (channel, source component) pair: its own sequence
number, MAVLink1 or MAVLink2 output, and MAVLink2 signing when given a key. MAVLink1 cannot carry ids > 255;
such messages are not sent on a MAVLink1 link, as in ArduPilot.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as mavlink
from pymavlink.generator.mavcrc import x25crc

from gcsd.wire import speedups

try:  # fastcrc is a dependency; the fallback keeps a broken install correct, only slower
    from fastcrc.crc16 import mcrf4xx as _mcrf4xx

    def _crc16(data: bytes) -> int:
        return _mcrf4xx(data)
except ImportError:  # pragma: no cover
    def _crc16(data: bytes) -> int:
        return x25crc(data).crc

crc16 = _crc16  # MAVLink's X.25 CRC, for the signing gateway (signgate.py), which re-frames
MAVLink_message = mavlink.MAVLink_message
STX_V1 = 0xFE
MAX_FRAME_BYTES = 280  # MAVLink2: 10 header + 255 payload + 2 CRC + 13 signature
STX_V2 = 0xFD


class _MessageInfo:
    """What routing needs of a message id: its CRC_EXTRA and where its target fields are."""

    __slots__ = ("crc_extra", "target_component_ofs", "target_system_ofs")

    def __init__(self, cls) -> None:
        self.crc_extra = cls.crc_extra
        tokens = re.findall(r"(\d*)([a-zA-Z?])", cls.unpacker.format)
        offsets, offset = {}, 0
        for name, (count, code) in zip(cls.ordered_fieldnames, tokens):
            offsets[name] = offset
            offset += struct.calcsize("<" + count + code)
        self.target_system_ofs = offsets.get("target_system", -1)
        self.target_component_ofs = offsets.get("target_component", -1)


MESSAGE_INFO: dict[int, _MessageInfo] = {msgid: _MessageInfo(cls) for msgid, cls in mavlink.mavlink_map.items()}
_decoder = mavlink.MAVLink(None)
_decoder.robust_parsing = False


class Frame:
    """One good frame as received: its bytes, header and routing targets; decoded on demand.

    Routing needs only the header and the target fields, read straight from the payload (a
    MAVLink2 payload may be truncated: a missing byte is zero). The pymavlink message object
    is built the first time `msg` is read, i.e. only for frames something local will handle.
    """

    __slots__ = (
        "_msg",
        "compid",
        "known",
        "msgid",
        "raw",
        "seq",
        "sysid",
        "target_component",
        "target_system",
        "version",
    )

    def __init__(self, raw: bytes, msgid: int, sysid: int, compid: int, seq: int, version: int,
                 known: bool, target_system: int = -1, target_component: int = -1) -> None:
        self.raw = raw
        self.msgid = msgid
        self.sysid = sysid
        self.compid = compid
        self.seq = seq
        self.version = version
        self.known = known
        self.target_system = target_system
        self.target_component = target_component
        self._msg = None

    @property
    def msg(self) -> MAVLink_message | None:
        if self._msg is None and self.known:
            self._msg = _decoder.decode(bytearray(self.raw))
        return self._msg

    @property
    def signed(self) -> bool:
        return self.version == 2 and bool(self.raw[2] & mavlink.MAVLINK_IFLAG_SIGNED)

    @property
    def name(self) -> str:
        return mavlink.mavlink_map[self.msgid].msgname if self.known else f"UNKNOWN_{self.msgid}"

    @classmethod
    def from_message(cls, msg: MAVLink_message) -> Frame:
        """A Frame for a message we built or decoded ourselves (tests, loopback)."""
        frames = FrameParser().feed(bytes(msg.get_msgbuf()))
        return frames[0]


@dataclass
class ParseStats:
    """What a parser saw; owned by the parser, summed into the channel's counters."""

    frames: int = 0
    bytes: int = 0
    parse_errors: int = 0
    crc_errors: int = 0
    unknown_ids: int = 0
    seq_gaps: int = 0
    # per source (sysid, compid): [last seq, frames, frames missing], the counts halved every
    # LOSS_WINDOW frames so they describe the recent link (`loss`)
    last_seq: dict[tuple[int, int], list[int]] = field(default_factory=dict)

    def loss(self, source: tuple[int, int]) -> tuple[float, int]:
        """The share of `source`'s frames that went missing lately (sequence gaps), and over how
        many frames that was measured (0: never heard)."""
        entry = self.last_seq.get(source)
        if entry is None:
            return 0.0, 0
        seen = entry[1] + entry[2]
        return (entry[2] / seen if seen else 0.0), seen


MAX_SOURCES_TRACKED = 256
LOSS_WINDOW = 256  # frames per source after which the loss counts are halved
MAX_GAP = 128  # a larger jump is a restart, a duplicate or reordering, not loss


class FrameParser:
    """Stream of bytes in, frames out. One per peer (a UDP client, a TCP connection, a serial port).

    Framing: find STX (0xFD MAVLink2, 0xFE MAVLink1), read the length, wait for the whole frame,
    check the CRC with the message's CRC_EXTRA. Bytes that are not a frame start are skipped in
    one step and counted once per run as a parse error. A MAVLink2 frame with unknown
    incompatibility flags is a parse error. A frame that fails its CRC is counted and the
    search restarts on the byte after its STX, so a real frame hidden behind a stray STX (noise
    on a serial line) is still found. A frame whose id the dialect does not know cannot have
    its CRC checked; it is passed on with `known = False` for the router to forward as a
    broadcast.
    """

    def __init__(self, stats: ParseStats | None = None, keep_bad_crc: bool = False) -> None:
        self.stats = stats if stats is not None else ParseStats()
        self._buf = b""
        self._keep_bad_crc = keep_bad_crc
        self.bad_crc_frames: list[bytes] = []  # frames that failed their CRC (forward_bad_crc); caller drains

    def pending_bytes(self) -> int:
        """Bytes held waiting for the rest of a frame (a truncated frame, if the stream ended)."""
        return len(self._buf)

    def reset(self) -> int:
        """Drop a partial frame (end of a UDP datagram); returns how many bytes were dropped."""
        dropped = len(self._buf)
        if dropped:
            self.stats.parse_errors += 1
        self._buf = b""
        return dropped

    def feed(self, data: bytes) -> list[Frame]:
        return _feed(self, data)


def feed_python(parser: FrameParser, data: bytes) -> list[Frame]:
    """FrameParser.feed in Python: the reference of the compiled one (gcsd.wire.speedups)."""
    stats = parser.stats
    stats.bytes += len(data)
    buf = parser._buf + data if parser._buf else bytes(data)
    n = len(buf)
    i = 0
    frames: list[Frame] = []
    info_of = MESSAGE_INFO.get
    while i < n:
        stx = buf[i]
        if stx != STX_V2 and stx != STX_V1:
            j = _next_stx(buf, i + 1)
            stats.parse_errors += 1
            i = j
            continue
        if stx == STX_V2:
            if n - i < 10:
                break
            plen = buf[i + 1]
            flags = buf[i + 2]
            if flags & ~mavlink.MAVLINK_IFLAG_SIGNED:
                stats.parse_errors += 1
                i += 1
                continue
            hlen = 10
            total = plen + 12 + (13 if flags else 0)
            if n - i < total:
                break
            seq, sysid, compid = buf[i + 4], buf[i + 5], buf[i + 6]
            msgid = buf[i + 7] | (buf[i + 8] << 8) | (buf[i + 9] << 16)
            version = 2
        else:
            if n - i < 6:
                break
            plen = buf[i + 1]
            hlen = 6
            total = plen + 8
            if n - i < total:
                break
            seq, sysid, compid, msgid = buf[i + 2], buf[i + 3], buf[i + 4], buf[i + 5]
            version = 1
        raw = buf[i:i + total]
        info = info_of(msgid)
        if info is None:
            stats.unknown_ids += 1
            frame = Frame(raw, msgid, sysid, compid, seq, version, False)
        else:
            crc_end = hlen + plen
            crc = _crc16(raw[1:crc_end] + bytes((info.crc_extra,)))
            if crc != raw[crc_end] | (raw[crc_end + 1] << 8):
                stats.crc_errors += 1
                if parser._keep_bad_crc:
                    parser.bad_crc_frames.append(raw)
                i += 1  # resync: the real frame may start inside this one
                continue
            ts_ofs, tc_ofs = info.target_system_ofs, info.target_component_ofs
            ts = tc = -1
            if ts_ofs >= 0:
                ts = raw[hlen + ts_ofs] if ts_ofs < plen else 0
            if tc_ofs >= 0:
                tc = raw[hlen + tc_ofs] if tc_ofs < plen else 0
            frame = Frame(raw, msgid, sysid, compid, seq, version, True, ts, tc)
        stats.frames += 1
        key = (sysid, compid)
        entry = stats.last_seq.get(key)
        if entry is not None:
            gap = (seq - entry[0] - 1) & 0xFF
            stats.seq_gaps += gap
            entry[0] = seq
            entry[1] += 1
            if gap < MAX_GAP:
                entry[2] += gap
            if entry[1] >= LOSS_WINDOW:
                entry[1] >>= 1
                entry[2] >>= 1
        elif len(stats.last_seq) < MAX_SOURCES_TRACKED:
            stats.last_seq[key] = [seq, 1, 0]
        frames.append(frame)
        i += total
    parser._buf = buf[i:] if i < n else b""
    return frames


_feed = speedups.compiled_feed(Frame, {
    msgid: (info.crc_extra, info.target_system_ofs, info.target_component_ofs) for msgid, info in MESSAGE_INFO.items()
}) or feed_python


def _next_stx(buf: bytes, start: int) -> int:
    a = buf.find(b"\xfd", start)
    b = buf.find(b"\xfe", start)
    if a < 0:
        return len(buf) if b < 0 else b
    return a if b < 0 or a < b else b


class Encoder:
    """Packs messages from one source (sysid, compid) onto one link; owns that link's sequence."""

    def __init__(self, sysid: int, compid: int) -> None:
        self._mav = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)

    def encode(self, msg: MAVLink_message, mavlink1: bool = False, sign: tuple[bytes, int, int] | None = None) -> bytes | None:
        """Pack for this link; `sign` = (key, link_id, timestamp) signs a MAVLink2 frame."""
        if mavlink1 and msg.get_msgId() > 255:
            return None
        mav = self._mav
        signing = mav.signing
        if sign is not None and not mavlink1:
            signing.secret_key, signing.link_id, signing.timestamp = sign
            signing.sign_outgoing = True
        else:
            signing.sign_outgoing = False
        raw = msg.pack(mav, force_mavlink1=mavlink1)
        mav.seq = (mav.seq + 1) & 0xFF
        return raw

