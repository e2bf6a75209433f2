"""One channel's output: the only writer to its peers. Pure of clocks: `now` and `wall` are set
by the asyncio layer once per wake-up (`WakeTime`, shared by the daemon's channels), never read here.

What goes out, and its checks, in this order:
- `write(raw)`: a forwarded frame, byte-exact. The out-gate (filter.out and rate caps,
  filters.py) may hold it back (counted by the gate); a muted high-latency link discards it
  (`muted`); the byte budget may refuse it (`drops`); else tlog, then every peer's writer.
- `send_message(msg, sysid, compid)`: one of our components' messages, encoded once per MAVLink
  version in use (each version with its own sequence numbers), signed when signing has a key.
- `reply(msg, sysid, compid)`: an answer (ACK, PARAM_VALUE, a service's reply). Sent at once when
  nothing is queued and the budget has room for a maximal frame; otherwise queued, in order, at
  most REPLY_QUEUE_MAX (the oldest dropped first, counted `replies_dropped`), and sent by
  `flush_replies()` from the next send pass once the budget has refilled. A reply is never
  dropped just because the link is busy: a radio link gets it late, not never.

The byte budget (`bandwidth`, bytes/s) is a token bucket holding at most 100 ms of traffic (and
at least one maximal frame). Scheduled telemetry asks `has_room` first and waits
(`budget_wait_s`); a forwarded frame that finds no budget is dropped and counted, never queued
without bound. A transport that reports its buffer full also counts as a drop. During the
services' turn of a send pass `share` (scheduler.ServiceShare) is set: `has_room` and
`budget_wait_s` then ask it too, and what is written is charged to it.
"""

from __future__ import annotations

from collections import deque

from gcsd.wire.codec import MAX_FRAME_BYTES, Encoder, MAVLink_message

REPLY_QUEUE_MAX = 64


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

    def charge(self, nbytes: int, now: float) -> None:
        """Take nbytes, or all there is (a share's account of what was sent, never refused)."""
        self._refill(now)
        self.tokens = max(0.0, self.tokens - nbytes)

    def wait_s(self, nbytes: int, now: float) -> float:
        """How long until nbytes may be sent."""
        self._refill(now)
        return max(0.0, (nbytes - self.tokens) / self.rate_bps)


class WakeTime:
    """The asyncio layer's time at the current wake-up, shared by every channel of a daemon (a
    frame received on one channel and written to another is written at the time it came in)."""

    __slots__ = ("now", "wall")

    def __init__(self) -> None:
        self.now = 0.0  # monotonic
        self.wall = 0.0  # wall clock: signing timestamps, tlog


class Outbox:
    """The output side of one channel (its peers are the channel's, shared by reference)."""

    def __init__(self, index: int, bandwidth: int | None, stats, peers: dict, output_enabled: bool = True, *,
                 wake_time: WakeTime | None = None, signing=None, tlog=None, gate=None) -> None:
        """`wake_time`: the daemon's, shared by every channel; `signing` (wire/signing.py) stamps
        our messages, `tlog` records what goes out, `gate` (filters.OutGate: filter.out and rate
        caps) may hold a forwarded frame back; each None when the daemon has none."""
        self.index = index
        self.stats = stats
        self.peers = peers
        self.v1_peers = 0  # peers that take MAVLink1 only (kept by the channel)
        self.time = wake_time or WakeTime()
        self.budget = TokenBucket(bandwidth, 0.0) if bandwidth else None
        self.output_enabled = output_enabled
        self.gate = gate
        self.tlog = tlog
        self.signing = signing
        self._encoders: dict[tuple[int, int, bool], Encoder] = {}
        self.replies: deque[tuple[MAVLink_message, int, int]] = deque()
        self.replies_dropped = 0
        self.share = None  # scheduler.ServiceShare: set by a send pass for its services' turn

    @property
    def now(self) -> float:
        return self.time.now

    # --- budget ----------------------------------------------------------------------------
    def has_room(self, nbytes: int = MAX_FRAME_BYTES) -> bool:
        return self._room(nbytes, True)

    def fits_now(self, nbytes: int = MAX_FRAME_BYTES) -> bool:
        """`has_room` for a sender that will not wait for room (an optional copy): in the
        services' turn its "no" does not hold the streams back."""
        return self._room(nbytes, False)

    def _room(self, nbytes: int, waits: bool) -> bool:
        budget = self.budget
        if budget is None:
            return True
        budget._refill(self.time.now)
        share = self.share
        if share is None:
            return budget.tokens >= nbytes
        return share.admits(nbytes, budget.tokens, budget.capacity, self.time.now, waits)

    def budget_wait_s(self, nbytes: int = MAX_FRAME_BYTES) -> float:
        if self.budget is None:
            return 0.0
        wait_s = self.budget.wait_s(nbytes, self.time.now)
        share = self.share
        return wait_s if share is None else max(wait_s, share.wait_s(nbytes, self.time.now))

    # --- forwarded frames ------------------------------------------------------------------
    def write(self, raw: bytes) -> bool:
        """Send raw bytes to every peer, if the budget allows; False (and a counted drop) if not.
        filter.out or a rate cap may hold it back (counted by the gate; not a failure of the link)."""
        peers = self.peers
        if not peers:
            return True  # nobody to send to is not a failure of the link
        gate = self.gate
        if gate is not None and not gate.allow(raw, self._clock):
            return True
        if len(peers) == 1 and self.budget is None and self.tlog is None and self.output_enabled:
            for peer in peers.values():  # the fast path: one peer, no budget, no tlog
                if peer.write(raw):
                    stats = self.stats
                    stats.packets_out += 1
                    stats.bytes_out += len(raw)
                    return True
                self.stats.drops += 1
                return False
        return self._write(raw, None)

    def _clock(self) -> float:
        return self.time.now

    def _write(self, raw: bytes, mavlink1: bool | None) -> bool:
        """Write to every peer, or to the peers of one version; budget, tlog and counters."""
        if not self.peers:
            return True
        if not self.output_enabled:
            self.stats.muted += 1
            return True  # discarded, as a disabled high-latency link discards everything
        budget = self.budget
        if budget is not None:
            if not budget.try_take(len(raw), self.time.now):
                self.stats.drops += 1
                return False
            if self.share is not None:
                self.share.charge(len(raw), self.time.now)
        if self.tlog is not None:
            self.tlog.record(raw, self.time.wall)
        sent = False
        for peer in list(self.peers.values()):
            if mavlink1 is not None and peer.mavlink1 != mavlink1:
                continue
            if peer.write(raw):
                sent = True
            else:
                self.stats.drops += 1
        if sent:
            self.stats.packets_out += 1
            self.stats.bytes_out += len(raw)
        return sent

    # --- our own messages ------------------------------------------------------------------
    def encoder(self, sysid: int, compid: int, mavlink1: bool = False) -> Encoder:
        enc = self._encoders.get((sysid, compid, mavlink1))
        if enc is None:
            enc = self._encoders[(sysid, compid, mavlink1)] = Encoder(sysid, compid)
        return enc

    def send_message(self, msg: MAVLink_message, sysid: int, compid: int) -> bool:
        """Encode a message from one of our components for the peers and write it."""
        peers = len(self.peers)
        if not peers:
            return True
        gate = self.gate  # once per message, whatever number of versions it is encoded in
        if gate is not None and not gate.allow_key(msg.get_msgId() << 16 | sysid << 8 | compid, self._clock):
            return True
        v1 = self.v1_peers
        if v1 == 0:
            return self._send_as(msg, sysid, compid, False, None)
        if v1 == peers:
            return self._send_as(msg, sysid, compid, True, None)
        sent_v2 = self._send_as(msg, sysid, compid, False, False)
        return self._send_as(msg, sysid, compid, True, True) and sent_v2

    def _send_as(self, msg: MAVLink_message, sysid: int, compid: int, mavlink1: bool, only: bool | None) -> bool:
        signing = self.signing
        sign = None
        if signing is not None and signing.key is not None and not mavlink1:
            sign = (signing.key, self.index & 0xFF, signing.next_timestamp(self.time.wall))
        raw = self.encoder(sysid, compid, mavlink1).encode(msg, mavlink1, sign)
        if raw is None:
            return True  # not representable in MAVLink1: nothing to send
        return self._write(raw, only)

    # --- replies ---------------------------------------------------------------------------
    def reply(self, msg: MAVLink_message, sysid: int, compid: int) -> bool:
        """Send now, or queue behind earlier replies until the budget has room; True unless the
        transport refused it (a full socket buffer: a counted drop)."""
        if not self.replies and self.has_room(MAX_FRAME_BYTES):
            return self.send_message(msg, sysid, compid)
        if not self.peers:
            return True
        if len(self.replies) >= REPLY_QUEUE_MAX:
            self.replies.popleft()
            self.replies_dropped += 1
        self.replies.append((msg, sysid, compid))
        return True

    def flush_replies(self) -> bool:
        """Send queued replies while the budget has room; True when none is left."""
        replies = self.replies
        while replies:
            if not self.has_room(MAX_FRAME_BYTES):
                return False
            msg, sysid, compid = replies.popleft()
            self.send_message(msg, sysid, compid)
        return True
