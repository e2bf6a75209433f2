"""Routing between channels: ArduPilot's rules (MAVLink_routing.cpp), as a pure function.

The route table learns (sysid, compid, channel) from every good frame on every channel, up to
MAX_ROUTES entries. Better than ArduPilot: when the table is full, the route seen least recently
is replaced if it has been silent for STALE_S, instead of new nodes being ignored forever.

`decide()` answers, for one received frame, "process it locally?" and "copy it to which
channels?". It never touches a socket or a clock; `now` is passed in. Rules, in order:

1. A frame from one of our own components (a loop) is ignored and not learned.
2. The source is learned (not sysid 0, not our own components, not our sysid with compid 0).
3. RADIO_STATUS / RADIO are processed locally and never forwarded.
4. HEARTBEAT goes to every active channel that is not private or no_forward, not the ingress
   channel, and has no route to the same (sysid, compid) already (a node is never told about
   itself). Processed locally.
5. Frames from a private or no_forward channel are never forwarded.
6. Exactly addressed to one of our components: processed locally, not forwarded.
7. Otherwise, per route on another channel: a broadcast (target system 0 or absent) goes to
   every channel with a route; a targeted frame goes to the channels where the target system was
   seen (and the target component, when the target system is ours). A private channel only gets
   frames addressed exactly to a node seen on it; a no_forward channel gets nothing.
8. Processed locally if it was addressed to us, or nothing was forwarded and the target system
   is ours, or it was a broadcast.

Groups (SPEC.md "Companion routing"): channels with the same `group` are redundant links to the
same systems (radio plus LTE to one flight controller). A route learned on one member is a route
on every member, so a frame that would go out on one goes out on all of them (those without a
peer write nothing); nothing received on a member goes back out on any member of its group (the
systems behind it already have it). The same frame arriving on two members is dropped by the
ingress's dedup (ingress.py, dedup.py) before it gets here.

Unknown message ids (no target field can be read) are forwarded as broadcasts and not processed,
but only from a source already learned from good frames on the same channel: their CRC cannot be
checked, so noise on a link would otherwise create routes and be re-broadcast everywhere. They
never create a route themselves. Never out of the ingress channel; at most one copy per channel.
"""

from __future__ import annotations

from dataclasses import dataclass

from gcsd.wire.msgids import HEARTBEAT as MSG_ID_HEARTBEAT
from gcsd.wire.msgids import RADIO, RADIO_STATUS

MAX_ROUTES = 20
STALE_S = 30.0


@dataclass(slots=True)
class Route:
    sysid: int
    compid: int
    channel: int
    mavtype: int | None
    last_seen_s: float


@dataclass(frozen=True, slots=True)
class ChannelPolicy:
    """What routing may do with a channel (from its configuration)."""

    private: bool = False
    no_forward: bool = False
    group: str | None = None  # redundant links to the same systems (see "Groups")


@dataclass(frozen=True, slots=True)
class Decision:
    process_locally: bool
    out_channels: tuple[int, ...] = ()


IGNORE = Decision(False)
_DECISIONS: dict[tuple[bool, tuple[int, ...]], Decision] = {}


def _decision(process: bool, out: tuple[int, ...] = ()) -> Decision:
    """The Decision for these values, made once: a frozen dataclass costs more to build than a
    routed frame's whole decision, and a daemon meets only a handful of distinct ones."""
    key = (process, out)
    d = _DECISIONS.get(key)
    if d is None:
        if len(_DECISIONS) >= 1024:  # channel sets of a many-channel daemon: bounded all the same
            _DECISIONS.clear()
        d = _DECISIONS[key] = Decision(process, out)
    return d


_NONE: list[Route] = []


class RouteTable:
    """Learned routes keyed by (sysid, compid, channel); bounded, with stale replacement.

    Indexed two more ways so that a decision costs what the frame's target costs, not what the
    table holds (250 routes of a fleet ground side as 20): the routes of each system id, and
    how many routes each channel has (the channels a broadcast goes to)."""

    def __init__(self, max_routes: int = MAX_ROUTES, stale_s: float = STALE_S) -> None:
        self._routes: dict[tuple[int, int, int], Route] = {}
        self._by_sysid: dict[int, list[Route]] = {}
        self._per_channel: dict[int, int] = {}  # channel -> routes through it (insertion-ordered)
        self.max_routes = max_routes
        self.stale_s = stale_s
        self.not_learned = 0  # new nodes refused because the table was full of live routes

    def __len__(self) -> int:
        return len(self._routes)

    def __iter__(self):
        return iter(self._routes.values())

    def learn(self, sysid: int, compid: int, channel: int, now: float, mavtype: int | None = None) -> None:
        key = (sysid, compid, channel)
        route = self._routes.get(key)
        if route is not None:
            route.last_seen_s = now
            if route.mavtype is None:
                route.mavtype = mavtype
            return
        if len(self._routes) >= self.max_routes and not self._evict_stale(now):
            self.not_learned += 1
            return
        route = self._routes[key] = Route(sysid, compid, channel, mavtype, now)
        self._by_sysid.setdefault(sysid, []).append(route)
        self._per_channel[channel] = self._per_channel.get(channel, 0) + 1

    def _remove(self, route: Route) -> None:
        del self._routes[(route.sysid, route.compid, route.channel)]
        same = self._by_sysid[route.sysid]
        same.remove(route)
        if not same:
            del self._by_sysid[route.sysid]
        left = self._per_channel[route.channel] - 1
        if left:
            self._per_channel[route.channel] = left
        else:
            del self._per_channel[route.channel]

    def _evict_stale(self, now: float) -> bool:
        oldest = min(self._routes.values(), key=lambda r: r.last_seen_s)
        if now - oldest.last_seen_s < self.stale_s:
            return False
        self._remove(oldest)
        return True

    def forget_channel(self, channel: int) -> None:
        """Every route through a channel that was closed at run time."""
        for route in [r for r in self._routes.values() if r.channel == channel]:
            self._remove(route)

    def has(self, sysid: int, compid: int, channel: int) -> bool:
        return (sysid, compid, channel) in self._routes

    def routes_of(self, sysid: int) -> list[Route]:
        """The routes to one system id, in the order they were learned."""
        return self._by_sysid.get(sysid, _NONE)

    def channels_with_routes(self):
        """The channels with at least one route, in the order their first route was learned."""
        return self._per_channel.keys()


class Router:
    """The routing decision for one process: our local components and each channel's policy."""

    def __init__(self, local: set[tuple[int, int]], policies: list[ChannelPolicy], table: RouteTable | None = None):
        self.local = frozenset(local)
        self.local_sysids = frozenset(s for s, _ in local)
        self.policies = list(policies)
        self.table = table if table is not None else RouteTable()
        self.unknown_dropped = 0  # unknown-id frames from sources never seen with a good frame
        self.members: dict[int, tuple[int, ...]] = {}
        self._group_members()

    def _group_members(self) -> None:
        """channel -> every channel of its group, itself included (only channels in a group)."""
        self.members = {
            ch: tuple(i for i, p in enumerate(self.policies) if p.group == policy.group)
            for ch, policy in enumerate(self.policies) if policy.group is not None
        }

    def set_policy(self, channel: int, policy: ChannelPolicy) -> None:
        """A channel opened at run time (livechannels.py), in a new slot or a retired one."""
        if channel == len(self.policies):
            self.policies.append(policy)
        else:
            self.policies[channel] = policy
        self._group_members()

    def decide(
        self,
        in_channel: int,
        msgid: int,
        sysid: int,
        compid: int,
        target_system: int,
        target_component: int,
        now: float,
        active_channels: set[int] | frozenset[int] = frozenset(),
        known_message: bool = True,
        mavtype: int | None = None,
    ) -> Decision:
        if (sysid, compid) in self.local:
            return IGNORE
        if not known_message:
            return self._unknown_message(in_channel, sysid, compid, now)
        if sysid != 0 and not (sysid in self.local_sysids and compid == 0):
            self.table.learn(sysid, compid, in_channel, now, mavtype)
        if msgid == RADIO_STATUS or msgid == RADIO:  # is_radio, inlined: this runs per frame
            return _decision(True)
        policy_in = self.policies[in_channel]
        closed_in = policy_in.private or policy_in.no_forward
        if msgid == MSG_ID_HEARTBEAT:
            if closed_in:
                return _decision(True)
            out = self._heartbeat_channels(in_channel, sysid, compid, active_channels)
            return _decision(True, self._grouped(out, in_channel) if self.members else out)

        broadcast_system = target_system <= 0
        broadcast_component = target_component <= 0
        match_system = broadcast_system or target_system in self.local_sysids
        addressed_to_us = match_system and (
            broadcast_component or self._local_compid(target_system, target_component, broadcast_system)
        )
        if closed_in:
            return _decision(addressed_to_us)
        if not broadcast_system and not broadcast_component and (target_system, target_component) in self.local:
            return _decision(True)

        out: list[int] = []
        policies = self.policies
        if broadcast_system:  # every channel with a route, but private ones (nothing is exactly theirs)
            for ch in self.table.channels_with_routes():
                policy = policies[ch]
                if ch != in_channel and not policy.no_forward and not policy.private:
                    out.append(ch)
        else:  # only the routes to the target system can match (the index: one lookup)
            remote = target_system not in self.local_sysids
            for route in self.table.routes_of(target_system):
                ch = route.channel
                if ch == in_channel or ch in out:
                    continue
                policy = policies[ch]
                if policy.no_forward:
                    continue
                if policy.private:
                    if target_component == route.compid:
                        out.append(ch)
                    continue
                if broadcast_component or remote or target_component == route.compid:
                    out.append(ch)
        process = addressed_to_us or (not out and match_system) or broadcast_system
        return _decision(process, self._grouped(out, in_channel) if self.members else tuple(out))

    def _unknown_message(self, in_channel: int, sysid: int, compid: int, now: float) -> Decision:
        policy = self.policies[in_channel]
        if policy.private or policy.no_forward or not self.table.has(sysid, compid, in_channel):
            self.unknown_dropped += 1
            return IGNORE
        self.table.learn(sysid, compid, in_channel, now)  # refresh only: the route exists
        return _decision(False, self.broadcast_channels(in_channel))

    def _grouped(self, out, in_channel: int) -> tuple[int, ...]:
        """`out` with each grouped channel widened to its whole group, minus the ingress group."""
        members = self.members
        skip = members.get(in_channel, (in_channel,))
        result: list[int] = []
        for ch in out:
            for m in members.get(ch, (ch,)):
                if m not in skip and m not in result and not self.policies[m].no_forward:
                    result.append(m)
        return tuple(result)

    def _local_compid(self, target_system: int, target_component: int, broadcast_system: bool) -> bool:
        if broadcast_system:
            return any(c == target_component for _, c in self.local)
        return (target_system, target_component) in self.local

    def _heartbeat_channels(self, in_channel: int, sysid: int, compid: int, active: set[int] | frozenset[int]):
        table = self.table
        return tuple(
            ch
            for ch in sorted(active)
            if ch != in_channel
            and not self.policies[ch].private
            and not self.policies[ch].no_forward
            and not table.has(sysid, compid, ch)
        )

    def broadcast_channels(self, in_channel: int) -> tuple[int, ...]:
        out = tuple(
            ch
            for ch in sorted(self.table.channels_with_routes())
            if ch != in_channel and not self.policies[ch].private and not self.policies[ch].no_forward
        )
        return self._grouped(out, in_channel) if self.members else out
