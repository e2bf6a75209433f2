"""Connections that have not authenticated yet: how many a tcp-server keeps, which one goes, when.

A tcp-server whose channel needs signatures serves a connection only after its first good
signed frame (channel.py, "Admission"); until then the connection is *waiting*. Pure rules over
the channel's waiting connections (Peer objects: `key` = (host, port), `last_rx_s` = when it
connected, since a waiting connection has sent no good frame):

- Slots: waiting and served connections together count against `max_peers`, but there is
  always one waiting slot (`waiting_slots`), so a station can still connect, authenticate and
  replace the served peer silent the longest (a half-open TCP connection is never swept).
  A channel therefore holds at most max_peers + 1 connections: that bounds its descriptors.
- Who goes when a new connection needs a slot (`evictee`): the oldest waiting connection of the
  host with the most waiting connections. A host that opens connections in a loop only ever
  pushes out its own; a station connecting from elsewhere keeps its slot long enough to send
  its first frame. A waiting connection never pushes out a served (authenticated) one.
- Timeout (`expired`): a connection still waiting UNAUTHENTICATED_TIMEOUT_S after it connected
  is closed. QGroundControl, MAVProxy, MAVSDK and Mission Planner send HEARTBEAT at 1 Hz from
  the moment they connect, so a station that has the key authenticates within about a second;
  ten heartbeat periods leave room for a slow start and TCP retransmissions, and bound how long
  an idle or garbage-sending connection (garbage and unsigned frames do not count as heard)
  holds a slot.

Every connection closed by these rules is counted as `unauthenticated_closed`. (Where the
channel needs no signature, connections are served at once and are peers like any other:
they count against max_peers, and one that has never sent a good frame is the first replaced;
they are not timed out, because a listen-only client, a telemetry logger, is legitimate there.)
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

UNAUTHENTICATED_TIMEOUT_S = 10.0


class Waiting(Protocol):
    key: object
    last_rx_s: float


def waiting_slots(max_peers: int, served: int) -> int:
    return max(1, max_peers - served)


def _host(key: object) -> object:
    return key[0] if isinstance(key, tuple) and key else key


def evictee(waiting: Mapping[object, Waiting]) -> object | None:
    """The key of the waiting connection to close for a new one (None: nothing waits)."""
    if not waiting:
        return None
    per_host: dict[object, int] = {}
    for key in waiting:
        host = _host(key)
        per_host[host] = per_host.get(host, 0) + 1
    most = max(per_host.values())
    return min((p for p in waiting.values() if per_host[_host(p.key)] == most), key=lambda p: p.last_rx_s).key


def expired(waiting: Mapping[object, Waiting], now: float,
            timeout_s: float = UNAUTHENTICATED_TIMEOUT_S) -> list[object]:
    return [key for key, p in waiting.items() if now - p.last_rx_s >= timeout_s]
