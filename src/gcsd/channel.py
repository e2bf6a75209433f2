"""A channel: one configured MAVLink link and the peers on it, independent of the transport.

A channel has one or more peers (each UDP client of a udp-server, each TCP connection, the one
serial port). Bytes from a peer go through that peer's FrameParser; good frames are handed to the
`on_frame` callback (the GCS object). Output goes to every peer of the channel.

Output version follows the peer: a channel starts in its configured version and then speaks the
version of the last frame it received. Forwarded frames are never converted.

The byte budget (`bandwidth`, bytes/s) is a token bucket holding at most 100 ms of traffic (and
at least one maximal frame). Scheduled telemetry waits for it; a frame that finds no budget is
dropped and counted, never queued without bound. A transport that reports its buffer full also
counts as a drop.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Protocol

from .codec import Encoder, Frame, FrameParser, MAVLink_message, ParseStats
from .config import ChannelConfig
from .router import ChannelPolicy

MAX_FRAME_BYTES = 280
UDP_PEER_TIMEOUT_S = 30.0
# ParseStats field -> the channel counter it is reported as
_INBOUND = {"frames": "packets_in", "bytes": "bytes_in", "parse_errors": "parse_errors",
            "crc_errors": "crc_errors", "unknown_ids": "unknown_ids", "seq_gaps": "seq_gaps"}


@dataclass
class ChannelStats:
    """Counters the channel owns; what came in (frames, bytes, errors, gaps) is counted by each
    peer's parser and summed in `Channel.snapshot()`."""

    packets_out: int = 0
    bytes_out: int = 0
    signature_rejects: int = 0
    drops: int = 0  # frames not sent for lack of budget or buffer space
    peers_forgotten: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class PeerWriter(Protocol):
    def __call__(self, data: bytes) -> bool: ...


class Peer:
    """One remote end on a channel: its parser, its writer and when it was last heard."""

    __slots__ = ("key", "last_rx_s", "parser", "write")

    def __init__(self, key: object, write: PeerWriter, now: float, keep_bad_crc: bool = False) -> None:
        self.key = key
        self.parser = FrameParser(ParseStats(), keep_bad_crc=keep_bad_crc)
        self.write = write
        self.last_rx_s = now


class TokenBucket:
    def __init__(self, rate_bps: float, now: float) -> None:
        self.rate_bps = float(rate_bps)
        self.capacity = max(self.rate_bps / 10.0, float(MAX_FRAME_BYTES))
        self.tokens = self.capacity
        self._last_s = now

    def _refill(self, now: float) -> None:
        if now > self._last_s:
            self.tokens = min(self.capacity, self.tokens + (now - self._last_s) * self.rate_bps)
            self._last_s = now

    def try_take(self, nbytes: int, now: float) -> bool:
        self._refill(now)
        if self.tokens < nbytes:
            return False
        self.tokens -= nbytes
        return True

    def wait_s(self, nbytes: int, now: float) -> float:
        """How long until nbytes may be sent."""
        self._refill(now)
        return max(0.0, (nbytes - self.tokens) / self.rate_bps)


class Channel:
    def __init__(self, index: int, config: ChannelConfig, clock: Callable[[], float] = time.monotonic) -> None:
        self.index = index
        self.config = config
        self.name = config.name
        self.clock = clock
        self.stats = ChannelStats()
        self.policy = ChannelPolicy(private=config.private, no_forward="no_forward" in config.options)
        self.peers: dict[object, Peer] = {}
        self.mavlink1 = config.mavlink == 1
        self.active = False  # has received something other than RADIO_STATUS
        self.budget = TokenBucket(config.bandwidth, clock()) if config.bandwidth else None
        self.local_address: tuple[str, int] | None = None
        self.on_frame: Callable[[Channel, Frame], None] = lambda channel, frame: None
        self.on_bad_crc: Callable[[Channel, bytes], None] = lambda channel, raw: None
        self.on_peer_joined: Callable[[Channel], None] = lambda channel: None
        self._encoders: dict[tuple[int, int], Encoder] = {}
        self._keep_bad_crc = "forward_bad_crc" in config.options
        self.unsigned_ok = "unsigned_ok" in config.options
        self.signing = None  # the process's Signing, set by the GCS; outgoing frames are signed when it has a key
        self.wall: Callable[[], float] = time.time
        self.signature_reject_reasons: dict[str, int] = {}
        self.tlog = None  # a TlogWriter shared by all channels, when log.tlog is set
        self._retired = ParseStats()  # counters of peers that are gone
        # a high-latency link is silent until CONTROL_HIGH_LATENCY enables it (REFERENCE.md 11)
        self.output_enabled = "high_latency" not in config.options
        self.muted_frames = 0

    # --- peers -----------------------------------------------------------------------------
    def add_peer(self, key: object, write: PeerWriter) -> Peer:
        peer = Peer(key, write, self.clock(), self._keep_bad_crc)
        self.peers[key] = peer
        self.on_peer_joined(self)
        return peer

    def remove_peer(self, key: object) -> None:
        peer = self.peers.pop(key, None)
        if peer is not None:
            self._retire(peer.parser.stats)

    def _retire(self, s: ParseStats) -> None:
        r = self._retired
        for name in _INBOUND:
            setattr(r, name, getattr(r, name) + getattr(s, name))

    def forget_silent_peers(self, now: float, timeout_s: float = UDP_PEER_TIMEOUT_S) -> list[object]:
        gone = [k for k, p in self.peers.items() if now - p.last_rx_s > timeout_s]
        for key in gone:
            self.remove_peer(key)
            self.stats.peers_forgotten += 1
        return gone

    # --- receive ---------------------------------------------------------------------------
    def receive(self, peer: Peer, data: bytes, datagram: bool = False) -> None:
        peer.last_rx_s = self.clock()
        frames = peer.parser.feed(data)
        if datagram and peer.parser.pending_bytes():
            peer.parser.reset()  # a datagram holds whole frames; the rest was truncated
        if peer.parser.bad_crc_frames:
            bad, peer.parser.bad_crc_frames = peer.parser.bad_crc_frames, []
            for raw in bad:
                self.on_bad_crc(self, raw)
        on_frame = self.on_frame
        for frame in frames:
            self.mavlink1 = frame.version == 1
            on_frame(self, frame)

    # --- send ------------------------------------------------------------------------------
    def encoder(self, sysid: int, compid: int) -> Encoder:
        enc = self._encoders.get((sysid, compid))
        if enc is None:
            enc = self._encoders[(sysid, compid)] = Encoder(sysid, compid)
        return enc

    def has_room(self, nbytes: int = MAX_FRAME_BYTES) -> bool:
        budget = self.budget
        if budget is None:
            return True
        budget._refill(self.clock())
        return budget.tokens >= nbytes

    def budget_wait_s(self, nbytes: int = MAX_FRAME_BYTES) -> float:
        return 0.0 if self.budget is None else self.budget.wait_s(nbytes, self.clock())

    def write(self, raw: bytes) -> bool:
        """Send raw bytes to every peer, if the budget allows; False (and a counted drop) if not."""
        if not self.peers:
            return True  # nobody to send to is not a failure of the link
        if not self.output_enabled:
            self.muted_frames += 1
            return True  # discarded, as a disabled high-latency link discards everything
        if self.budget is not None and not self.budget.try_take(len(raw), self.clock()):
            self.stats.drops += 1
            return False
        if self.tlog is not None:
            self.tlog.record(raw, self.wall())
        sent = False
        for peer in list(self.peers.values()):
            if peer.write(raw):
                sent = True
            else:
                self.stats.drops += 1
        if sent:
            self.stats.packets_out += 1
            self.stats.bytes_out += len(raw)
        return sent

    def send_message(self, msg: MAVLink_message, sysid: int, compid: int) -> bool:
        """Encode a message from one of our components for this link and write it."""
        signing = self.signing
        sign = None
        if signing is not None and signing.key is not None and not self.mavlink1:
            sign = (signing.key, self.index & 0xFF, signing.next_timestamp(self.wall()))
        raw = self.encoder(sysid, compid).encode(msg, self.mavlink1, sign)
        if raw is None:
            return True  # not representable on this link version: nothing to send
        return self.write(raw)

    # --- counters --------------------------------------------------------------------------
    def snapshot(self) -> dict[str, int]:
        """Counters of the channel and all its peers, past and present."""
        out = self.stats.as_dict()
        parse = [p.parser.stats for p in self.peers.values()] + [self._retired]
        for name, key in _INBOUND.items():
            out[key] = sum(getattr(s, name) for s in parse)
        out["peers"] = len(self.peers)
        for reason, n in self.signature_reject_reasons.items():
            out[f"signature_rejects_{reason}"] = n
        return out
