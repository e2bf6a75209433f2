"""The ingress decision: where every frame's fate is decided, once (REVIEW.md B.3). Pure: `now`
and `wall` are passed in; no socket, no clock, no channel object beyond the `Ingressing` port.

A frame reaches here after the channel has parsed it, admitted its peer and applied its input
filter (links/channel.py). In this order:

0. `verify(channel, frame, wall)`: the signing check (wire/signing.py), before anything else looks
   at the frame: None, or why it is refused (counted by the channel, nothing else changes).
1. `decide(channel, frame, now, wall) -> Fate`:
   1. a duplicate: the same bytes came in lately on a member of the same redundant group, or on
      any channel with `routing.dedup_ms` (dedup.py): DUPLICATE, counted `duplicates`;
   2. a loop: bytes this daemon forwarded less than LOOP_WINDOW_S ago, back again: LOOP, counted
      `loop_dropped`;
   3. accepted: the channel is active from now on (anything but RADIO_STATUS / RADIO), the router
      learns the source and says where it goes (router.py). The Fate says
      - `forward`: the channels to write the frame to (its bytes are remembered for rule 2),
      - `sign`: a sign_forwarded channel with a key: the signing gateway signs it first
        (signgate.py; `signed(...)` gives the bytes, remembered for rule 2 instead),
      - `local`: our components handle the decoded message,
      - `tap`: every accepted frame is shown to the taps (HTTP message tree, log capture),
      - `streams`: the channel asks for streams for its ground stations (streamreq.py).
2. `bad_crc(channel, raw, now)`: a frame with a bad CRC on a `forward_bad_crc` channel goes out
   unchanged as a broadcast (never processed), unless it is a loop.

Fates are built once per distinct value (a frame costs a dictionary lookup, not an object). The
adapter (daemon/daemon.py) applies a fate: taps, writes, stream requests, local dispatch. The
next step puts the sender's authority here (SPEC.md "Authority").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

from gcsd.routing.authority import ADMIN, OPERATOR, needs_decoding, refusal, required_for_frame
from gcsd.routing.dedup import LOOP_WINDOW_S, RecentFrames
from gcsd.routing.router import Router
from gcsd.routing.signgate import signed_copy
from gcsd.wire.codec import Frame
from gcsd.wire.msgids import HEARTBEAT, SYSTEM_TIME, is_radio


class Ingressing(Protocol):
    """What the ingress reads of the channel a frame came in on."""

    index: int
    dedup: bool
    sign_forwarded: bool
    unsigned_ok: bool
    stream_requests: object | None


@dataclass(frozen=True, slots=True)
class Fate:
    drop: str | None  # None (accepted), "duplicates" or "loop_dropped": the counter it goes to
    forward: tuple[int, ...] = ()
    sign: bool = False
    local: bool = False
    tap: bool = False
    streams: bool = False
    refuse: str | None = None  # DENIED: the refusal the protocol answers with (authority.REFUSE_*)


DUPLICATE = Fate("duplicates")
LOOP = Fate("loop_dropped")
DENIED = "denied"
_DENIED_FATES = {}  # refusal -> Fate


class Ingress:
    def __init__(self, router: Router, signing, dedup_ms: int = 0) -> None:
        """`signing`: the daemon's Signing (its key, checks and timestamps, wire/signing.py);
        `dedup_ms`: routing.dedup_ms (0: only the frames of redundant link groups are checked,
        within LOOP_WINDOW_S)."""
        self.router = router
        self.signing = signing
        self.active: set[int] = set()  # channels that carried anything but a radio's own reports
        self.loops = RecentFrames(LOOP_WINDOW_S)  # frames forwarded lately: one coming back is a loop
        self.dedup = RecentFrames(dedup_ms / 1000 if dedup_ms else LOOP_WINDOW_S)
        self.dedup_all = dedup_ms > 0
        self.bad_crc_forwarded = 0
        self._fates: dict[tuple, Fate] = {}
        self.roles_in_force = False
        self._channel_roles: list[int] = []  # by channel index; missing: ADMIN
        self.last_role = ADMIN  # the role decide() gave the last frame (for the audit of a denial)
        self.denied = 0

    def set_roles(self, channel_roles: list[int], station_keys: bool) -> None:
        """Roles in force: each channel's role for its unsigned peers, and whether station keys
        are configured (a role below ADMIN anywhere turns the check on)."""
        self._channel_roles = list(channel_roles)
        self.roles_in_force = station_keys or any(role < ADMIN for role in channel_roles)

    def role_of(self, channel: Ingressing) -> int:
        """The role of the frame just verified on `channel`: its key's, else the channel's."""
        key = self.signing.verified_by
        if key is not None:
            return key.role
        roles, index = self._channel_roles, channel.index
        return roles[index] if index < len(roles) else ADMIN

    def verify(self, channel: Ingressing, frame: Frame, wall: float) -> str | None:
        """The signing check: None (accepted) or the reason the frame is refused."""
        signing = self.signing
        if not signing.checks_needed:
            return None
        return signing.check(frame.raw, frame.msgid, frame.sysid, frame.compid, channel.unsigned_ok, wall)

    def decide(self, channel: Ingressing, frame: Frame, now: float) -> Fate:
        raw, index = frame.raw, channel.index
        if (channel.dedup or self.dedup_all) and self.dedup.check(raw, now):
            return DUPLICATE
        if self.loops.seen(raw, now):
            return LOOP
        msgid = frame.msgid
        if index not in self.active and not is_radio(msgid):
            self.active.add(index)
        role = ADMIN
        if self.roles_in_force:
            role = self.last_role = self.role_of(channel)
            if role < ADMIN:
                msg = frame.msg if frame.known and needs_decoding(msgid) else None
                if role < required_for_frame(msgid, msg):
                    self.denied += 1
                    return self._denied(msgid)
        heartbeat = msgid == HEARTBEAT
        decision = self.router.decide(
            index, msgid, frame.sysid, frame.compid, frame.target_system, frame.target_component,
            now, self.active, frame.known, frame.msg.type if heartbeat and frame.known else None,
        )
        out = decision.out_channels
        sign = bool(out) and channel.sign_forwarded and self.signing.key is not None and role >= OPERATOR
        streams = channel.stream_requests is not None and (heartbeat or msgid == SYSTEM_TIME)
        if out and not sign:
            self.loops.remember(raw, now)  # the bytes that go out: what a loop brings back
        key = (out, sign, decision.process_locally and frame.known, streams)
        fate = self._fates.get(key)
        if fate is None:
            fate = self._fates[key] = Fate(None, out, sign, key[2], True, streams)
        return fate

    @staticmethod
    def _denied(msgid: int) -> Fate:
        kind = refusal(msgid)
        fate = _DENIED_FATES.get(kind)
        if fate is None:
            fate = _DENIED_FATES[kind] = Fate(DENIED, tap=True, refuse=kind)
        return fate

    def signed(self, channel: Ingressing, raw: bytes, now: float, wall: float) -> bytes:
        """The signing gateway: the bytes a `sign` fate forwards (signed, link id = the channel's
        index), remembered for the loop check."""
        signing = self.signing
        out = signed_copy(raw, signing.key, channel.index, signing.next_timestamp(wall))
        out = raw if out is None else out
        self.loops.remember(out, now)
        return out

    def bad_crc(self, channel: Ingressing, raw: bytes, now: float) -> tuple[int, ...] | None:
        """Where a bad-CRC frame of a forward_bad_crc channel goes: every broadcast channel, or
        None if it is a loop (counted `loop_dropped`)."""
        if self.loops.seen(raw, now):
            return None
        self.loops.remember(raw, now)
        self.bad_crc_forwarded += 1
        return self.router.broadcast_channels(channel.index)
