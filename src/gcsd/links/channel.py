"""A channel: one configured MAVLink link and the peers on it, independent of the transport.

A channel has peers (each ground station of a udp-server, each TCP connection, the one serial
port or remote of a client channel). Bytes from a peer go through that peer's FrameParser.

Receive, per frame, in this order (SPEC "Signing", "Channels"):
1. `receiver.verify(channel, frame)` (the ingress's signing check) comes before anything else looks at the frame.
   A frame that fails it is counted as a reject (`on_reject`) and changes nothing else: no
   peer, no route, no version, no activity, no packets_in.
2. The frame is accepted from its peer: the peer's last-heard time, its output version, and
   its admission (below). Version: a peer starts in the channel's configured version until its
   first good frame, which sets it (a ground station that speaks only MAVLink1 gets MAVLink1);
   from then on it only goes up, to MAVLink2 once the peer sends MAVLink2 (ArduPilot's rule),
   so one MAVLink1 station never changes what another gets. RADIO_STATUS and RADIO (a radio's
   own reports) count for nothing.
3. `receiver.on_frame(channel, frame, now)`: the ingress decision and its application (daemon.py).

Steps 1-3 run inside the receive boundary (boundary.py): an exception in one frame's signing
check, admission, routing or handling is counted under "receive" and the next frame goes on; a
TCP connection is never closed by it.

Admission (no amplification): a udp-server answers an address only after a good frame from it;
datagrams from unknown addresses go through one shared parser (a datagram holds whole frames,
so nothing carries over between them) and cost no state. A tcp-server connection is served at
once when the channel needs no signature (TCP cannot be spoofed and a plain pymavlink client
waits for our HEARTBEAT first), otherwise only after a good signed frame. Client and serial
channels have their one peer from the start. At most `max_peers` peers are served; a new one
replaces a connection that has not sent a good frame yet, else the peer silent the longest. A udp-server forgets a peer silent for 30 s (`sweep`).
Connections waiting to authenticate count against max_peers too (one waiting slot is always
left), the oldest of the host holding the most goes first, and one still waiting after
UNAUTHENTICATED_TIMEOUT_S is closed: unauth.py has the rules and why.

Output: every admitted peer gets every frame. Forwarded frames go out byte-exact; our own
messages are encoded once per version in use on the channel (usually once, MAVLink2 signed
when signing is active), each version with its own sequence numbers.

The output side (outbox.py) is the only writer: budget, encoders, signing stamp, tlog and a
bounded queue of replies sent as the budget refills. The channel reads no clock: the asyncio
layer hands it `now` (receive) and `tick(now, wall)` once per wake-up.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Protocol

from gcsd.boundary import ErrorCounts
from gcsd.config import ChannelConfig
from gcsd.links import unauth
from gcsd.links.outbox import Outbox, WakeTime
from gcsd.routing.filters import counters as gate_counters
from gcsd.routing.filters import gates
from gcsd.routing.router import ChannelPolicy
from gcsd.routing.streamreq import StreamRequests
from gcsd.wire.codec import MAX_FRAME_BYTES, STX_V2, Encoder, Frame, FrameParser, MAVLink_message, ParseStats
from gcsd.wire.msgids import RADIO_IDS

UDP_PEER_TIMEOUT_S = 30.0
PEER_SWEEP_INTERVAL_S = 1.0
DEFAULT_MAX_PEERS = 8
# ParseStats field -> the channel counter it is reported as
_INBOUND = {"frames": "packets_in", "bytes": "bytes_in", "parse_errors": "parse_errors",
            "crc_errors": "crc_errors", "unknown_ids": "unknown_ids", "seq_gaps": "seq_gaps"}
_NO_STATE = RADIO_IDS  # a radio's own reports: they say nothing about the peer


@dataclass
class ChannelStats:
    """Counters the channel owns; what came in (frames, bytes, errors, gaps) is counted by each
    peer's parser and summed in `Channel.snapshot()`."""

    packets_out: int = 0
    bytes_out: int = 0
    signature_rejects: int = 0
    drops: int = 0  # frames not sent for lack of budget or buffer space
    peers_forgotten: int = 0  # silent for UDP_PEER_TIMEOUT_S
    peers_replaced: int = 0  # dropped for a new peer when max_peers were served
    muted: int = 0  # frames discarded while a high-latency link's output is disabled
    spoofed_dropped: int = 0  # frames of a payload with a frame from a source its link may not carry (mqtt)
    retained_dropped: int = 0  # retained MQTT messages: stored by the broker, not sent now; never acted on
    duplicates: int = 0  # the same frame again: a redundant link of a group, or routing.dedup_ms (dedup.py)
    open_failures: int = 0  # attempts to open the transport that failed (a device missing, a name not resolving)
    loop_dropped: int = 0  # frames that came back after gcsd had forwarded them (a forwarding loop, dedup.py)
    denied: int = 0  # frames whose sender's role does not allow their message (routing/authority.py)
    unauthenticated_closed: int = 0  # connections closed before their first good frame (unauth.py)
    accept_failures: int = 0  # tcp-server accept() refused by the system (out of descriptors...; tcpserver.py)

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class PeerWriter(Protocol):
    def __call__(self, data: bytes) -> bool: ...


class Peer:
    """One remote end on a channel: its parser, its writer, when it was last heard (a good
    frame), the MAVLink version it gets, and whether it is served (admitted)."""

    __slots__ = ("admitted", "close", "heard", "key", "last_rx_s", "mavlink1", "parser", "write")

    def __init__(self, key: object, write: PeerWriter | None, now: float, parser: FrameParser,
                 mavlink1: bool = False, close: Callable[[], None] | None = None) -> None:
        self.key = key
        self.parser = parser
        self.write = write
        self.last_rx_s = now
        self.mavlink1 = mavlink1
        self.admitted = False
        self.heard = False  # a good frame has set its version
        self.close = close


def _source_of(raw: bytes) -> int:
    return raw[5] if raw[0] == STX_V2 else raw[3]


class Receiver(Protocol):
    """Where a channel's frames go (the daemon: routing/ingress.py decides, daemon.py applies)."""

    def verify(self, channel: Channel, frame: Frame) -> str | None:
        """The signing check: None (accepted) or why the frame is refused."""

    def on_frame(self, channel: Channel, frame: Frame, now: float) -> None:
        """An accepted frame: routing and local handling."""

    def on_reject(self, channel: Channel, frame: Frame, reason: str, now: float) -> None:
        """A frame that failed the signing check."""

    def on_bad_crc(self, channel: Channel, raw: bytes, now: float) -> None:
        """A bad-CRC frame on a forward_bad_crc channel, from an admitted peer."""

    def on_peer_joined(self, channel: Channel, peer: Peer) -> None:
        """A peer served for the first time."""


class Unwired:
    """A Receiver that accepts every frame and does nothing with it (tools; tests pass their own)."""

    def verify(self, channel: Channel, frame: Frame) -> str | None:
        return None

    def on_frame(self, channel: Channel, frame: Frame, now: float) -> None:
        pass

    def on_reject(self, channel: Channel, frame: Frame, reason: str, now: float) -> None:
        pass

    def on_bad_crc(self, channel: Channel, raw: bytes, now: float) -> None:
        pass

    def on_peer_joined(self, channel: Channel, peer: Peer) -> None:
        pass


class Channel:
    outbox_class = Outbox  # a channel of another kind brings its own output (api/http/local.py)

    def __init__(self, index: int, config: ChannelConfig, clock: Callable[[], float] = time.monotonic, *,
                 receiver: Receiver | None = None, wake_time: WakeTime | None = None, signing=None,
                 tlog=None, errors: ErrorCounts | None = None, wall: Callable[[], float] = time.time,
                 signing_required: bool = False) -> None:
        """`receiver`: where frames go (Unwired: nowhere); `wake_time`: the asyncio layer's time,
        shared by the daemon's channels; `signing`, `tlog`, `errors`: the daemon's; `clock` and
        `wall`: what the asyncio layer reads at a wake-up (it ticks the channel);
        `signing_required`: signing.require (a tcp-server then serves a connection only after a
        good signed frame, unless the channel is unsigned_ok)."""
        receiver = receiver or Unwired()
        self.index = index
        self.config = config
        self.name = config.name
        self.clock = clock
        self.stats = ChannelStats()
        self.policy = ChannelPolicy(private=config.private, no_forward="no_forward" in config.options,
                                    group=config.group)
        self.peers: dict[object, Peer] = {}  # admitted: served
        self._waiting: dict[object, Peer] = {}  # stream connections not served yet
        self.max_peers = getattr(config, "max_peers", None) or DEFAULT_MAX_PEERS
        self._start_v1 = config.mavlink == 1
        # the output side: budget, encoders, signing stamp, tlog, the reply queue (outbox.py)
        self.in_gate, out_gate = gates(config)  # companion routing (filters.py): None without filter/cap
        self.out = self.outbox_class(index, config.bandwidth, self.stats, self.peers,
                                     "high_latency" not in config.options, wake_time=wake_time,
                                     signing=signing, tlog=tlog, gate=out_gate)
        self.local_address: tuple[str, int] | None = None
        self.receiver = receiver
        self.on_frame = receiver.on_frame  # bound once: called per frame
        self.make_writer: Callable[[object], PeerWriter] | None = None  # the transport's, for admitted strangers
        self._keep_bad_crc = "forward_bad_crc" in config.options
        self._strangers = FrameParser(ParseStats(), keep_bad_crc=False)  # datagrams from unknown addresses
        # a signing gateway's own unsigned frames are accepted: they are what it signs (signgate.py)
        self.sign_forwarded = "sign_forwarded" in config.options
        self.unsigned_ok = "unsigned_ok" in config.options or self.sign_forwarded
        # tcp-server: serve a connection before its first good frame (TCP cannot be spoofed: no
        # amplification), unless signatures are required on it
        self.serve_on_connect = not (signing_required and not self.unsigned_ok)
        self.signature_reject_reasons: dict[str, int] = {}
        self.errors = errors if errors is not None else ErrorCounts()
        self.wall = wall
        self._retired = ParseStats()  # counters of peers that are gone
        self._rejected_frames = 0
        self._rejected_bytes = 0
        self._last_sweep_s = 0.0
        self.dedup = config.group is not None  # same frames dropped (a group; all channels with routing.dedup_ms)
        self.retired = False  # removed at run time: its slot waits for the next added channel (livechannels.py)
        self.stream_requests = StreamRequests(config.request_streams) if config.request_streams else None

    # --- peers -----------------------------------------------------------------------------
    @property
    def mavlink1(self) -> bool:
        """True when no peer takes MAVLink2 (then only MAVLink1 goes out)."""
        return self.out.v1_peers == len(self.peers) if self.peers else self._start_v1

    def _new_parser(self) -> FrameParser:
        return FrameParser(ParseStats(), keep_bad_crc=self._keep_bad_crc)

    def add_peer(self, key: object, write: PeerWriter, now: float | None = None, announce: bool = True) -> Peer:
        """A peer served from the start (the remote of a client channel, a serial port); with
        `announce`, the receiver hears that it joined (a channel's own permanent peer: not)."""
        peer = Peer(key, write, self.out.time.now if now is None else now, self._new_parser(), self._start_v1)
        self._admit(peer, announce)
        return peer

    def connect_peer(self, key: object, write: PeerWriter, close: Callable[[], None] | None = None) -> Peer:
        """A tcp-server connection: served now, or after its first good frame (`serve_on_connect`)."""
        peer = Peer(key, write, self.out.time.now, self._new_parser(), self._start_v1, close)
        if self.serve_on_connect:
            self._admit(peer)
            return peer
        if len(self._waiting) >= unauth.waiting_slots(self.max_peers, len(self.peers)):
            self._close_unauthenticated(self._waiting[unauth.evictee(self._waiting)])
        self._waiting[key] = peer
        return peer

    def _close_unauthenticated(self, peer: Peer) -> None:
        """A connection that never authenticated, closed for a newer one or after its timeout (unauth.py)."""
        self.remove_peer(peer.key)
        self.stats.unauthenticated_closed += 1
        if peer.close is not None:
            peer.close()

    def stranger(self, key: object, now: float) -> Peer:
        """A datagram's sender that is not a peer: parsed by the shared parser, served only if
        one of its frames is accepted."""
        return Peer(key, None, now, self._strangers, self._start_v1)

    def _admit(self, peer: Peer, announce: bool = True) -> None:
        if len(self.peers) >= self.max_peers:
            # a connection that never sent a good frame goes first (the oldest of the host holding
            # the most: a host opening connections in a loop pushes out its own), then the peer
            # silent the longest
            unheard = {k: p for k, p in self.peers.items() if not p.heard}
            silent = self.peers[unauth.evictee(unheard)] if unheard else min(
                self.peers.values(), key=lambda p: p.last_rx_s)
            self.remove_peer(silent.key)
            self.stats.peers_replaced += 1
            self.stats.unauthenticated_closed += not silent.heard
            if silent.close is not None:
                silent.close()
        if peer.write is None:
            peer.write = self.make_writer(peer.key)
        if peer.parser is self._strangers:
            peer.parser = self._new_parser()  # its next datagrams get a parser of its own
        self._waiting.pop(peer.key, None)
        peer.admitted = True
        self.peers[peer.key] = peer
        self.out.v1_peers += peer.mavlink1
        if announce:
            self.receiver.on_peer_joined(self, peer)

    def _set_version(self, peer: Peer, mavlink1: bool) -> None:
        peer.heard = True
        if peer.admitted:
            self.out.v1_peers += mavlink1 - peer.mavlink1
        peer.mavlink1 = mavlink1

    def remove_peer(self, key: object) -> None:
        peer = self.peers.pop(key, None)
        if peer is not None:
            self.out.v1_peers -= peer.mavlink1
        else:
            peer = self._waiting.pop(key, None)
        if peer is not None:
            self._retire(peer.parser.stats)

    def drop_all_peers(self) -> None:
        for key in [*self.peers, *self._waiting]:
            self.remove_peer(key)

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

    def sweep(self, now: float) -> list[object]:
        """Checked once a second: connections still unauthenticated after their timeout are closed
        (unauth.py); a udp-server's peers silent for UDP_PEER_TIMEOUT_S are forgotten (returned)."""
        if now - self._last_sweep_s < PEER_SWEEP_INTERVAL_S:
            return []
        self._last_sweep_s = now
        for key in unauth.expired(self._waiting, now):
            self._close_unauthenticated(self._waiting[key])
        if self.config.type != "udp-server":
            return []
        return self.forget_silent_peers(now)

    # --- receive ---------------------------------------------------------------------------
    def receive(self, peer: Peer, data: bytes, now: float, datagram: bool = False,
                source_sysid: int | None = None) -> None:
        """With `source_sysid` (an mqtt ground side: the S of T/up/S/C), every frame the parser
        finds must come from that system, or the whole payload is dropped (`spoofed_dropped`)."""
        self.out.time.now = now
        parser = peer.parser
        frames = parser.feed(data)
        if datagram and parser.pending_bytes():
            parser.reset()  # a datagram holds whole frames; the rest was truncated
        if source_sysid is not None and self._spoofed(parser, frames, source_sysid):
            return
        if parser.bad_crc_frames:
            bad, parser.bad_crc_frames = parser.bad_crc_frames, []
            if peer.admitted:  # never relay what an unknown source sent
                for raw in bad:
                    self.receiver.on_bad_crc(self, raw, now)
        verify, on_frame, tlog, in_gate = self.receiver.verify, self.on_frame, self.out.tlog, self.in_gate
        signing = self.out.signing  # without a key or `require`, every frame is accepted untouched
        checked = signing is None or signing.key is not None or signing.require
        for frame in frames:
            try:  # the receive boundary: one frame's failure is counted, the rest of the batch goes on
                if tlog is not None:
                    tlog.record(frame.raw, self.out.time.wall)
                reason = verify(self, frame) if checked else None
                if reason is not None:
                    self._rejected_frames += 1
                    self._rejected_bytes += len(frame.raw)
                    self.receiver.on_reject(self, frame, reason, now)
                    continue
                if frame.msgid not in _NO_STATE:
                    peer.last_rx_s = now
                    if peer.mavlink1 and frame.version == 2 or not peer.heard:
                        self._set_version(peer, frame.version == 1)
                    if not peer.admitted:
                        self._admit(peer)
                if in_gate is not None and not in_gate.allow(frame):
                    continue  # filter.in: after the signature check, before routing and local handling
                on_frame(self, frame, now)
            except Exception:  # noqa: BLE001  (one frame's failure must not end the batch or the connection)
                self.errors.failed("receive", now, channel=self.name, msg=frame.name, sysid=frame.sysid)

    def _spoofed(self, parser: FrameParser, frames: list[Frame], source_sysid: int) -> bool:
        """Checked on what the parser found (not on the payload's first bytes): a frame hidden
        behind garbage, a second frame, or one inside a frame that failed its CRC counts too."""
        bad = parser.bad_crc_frames
        if all(f.sysid == source_sysid for f in frames) and all(_source_of(raw) == source_sysid for raw in bad):
            return False
        parser.bad_crc_frames = []
        self.stats.spoofed_dropped += len(frames) + len(bad)
        self._rejected_frames += len(frames)
        self._rejected_bytes += sum(len(f.raw) for f in frames)
        return True

    # --- send (outbox.py) -------------------------------------------------------------------
    def tick(self, now: float, wall: float) -> None:
        """The asyncio layer's time at this wake-up, for everything done until the next one."""
        time = self.out.time
        time.now = now
        time.wall = wall

    def encoder(self, sysid: int, compid: int, mavlink1: bool = False) -> Encoder:
        return self.out.encoder(sysid, compid, mavlink1)

    def has_room(self, nbytes: int = MAX_FRAME_BYTES) -> bool:
        return self.out.has_room(nbytes)

    def reply_goes_now(self) -> bool:
        """A reply would go out at once: none queued ahead of it and room in the byte budget (what
        an optional copy waits for: it never queues, so it never pushes out an owed reply)."""
        return not self.out.replies and self.out.fits_now(MAX_FRAME_BYTES)

    def budget_wait_s(self, nbytes: int = MAX_FRAME_BYTES) -> float:
        return self.out.budget_wait_s(nbytes)

    def write(self, raw: bytes) -> bool:
        return self.out.write(raw)

    def send_message(self, msg: MAVLink_message, sysid: int, compid: int) -> bool:
        return self.out.send_message(msg, sysid, compid)

    # --- counters --------------------------------------------------------------------------
    def loss(self, sysid: int, compid: int) -> tuple[float, int]:
        """How lossy the link from (sysid, compid) has been lately, measured by the sequence gaps
        its peer's parser saw: (share of frames missing, frames measured over)."""
        best = (0.0, 0)
        for peer in self.peers.values():
            measured = peer.parser.stats.loss((sysid, compid))
            if measured[1] > best[1]:
                best = measured
        return best

    def snapshot(self) -> dict[str, int]:
        """Counters of the channel and all its peers, past and present. packets_in and bytes_in
        count accepted frames only: a rejected frame shows in signature_rejects alone."""
        out = self.stats.as_dict()
        parse = [p.parser.stats for p in self.peers.values()] + [p.parser.stats for p in self._waiting.values()]
        parse += [self._retired, self._strangers.stats]
        for name, key in _INBOUND.items():
            out[key] = sum(getattr(s, name) for s in parse)
        out["packets_in"] -= self._rejected_frames
        out["bytes_in"] -= self._rejected_bytes
        out["peers"] = len(self.peers)
        out["replies_dropped"] = self.out.replies_dropped
        out.update(gate_counters(self.in_gate, self.out.gate))
        for reason, n in self.signature_reject_reasons.items():
            out[f"signature_rejects_{reason}"] = n
        return out
