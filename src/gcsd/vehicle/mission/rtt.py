"""Round-trip estimates and retransmission timeouts per peer, in the manner of RFC 6298. Pure.

Used wherever the vehicle decides when to ask again: today the mission, fence and rally uploads
(gcsd.vehicle.mission.transfer re-requests a missing item). The ground station drives every other
transfer: parameter lists (it re-requests what it missed; gcsd paces the list by the link's byte
budget and answers a read at once) and FTP (the client re-sends; gcsd paces bursts, ftp/burst.py).

**Estimator** (RFC 6298 section 2, alpha = 1/8, beta = 1/4, K = 4):

    no sample yet:   RTO = initial_s               (INITIAL_RTO_S, 250 ms, at most the ceiling)
    first sample R:  SRTT = R, RTTVAR = R / 2
    later samples:   RTTVAR = 3/4 RTTVAR + 1/4 |SRTT - R|;  SRTT = 7/8 SRTT + 1/8 R
    RTO = clamp(SRTT + max(G, K * RTTVAR), MIN_RTO_S, max_s)

G = GRANULARITY_S (10 ms): an asyncio timer on a busy two-core machine is this late, and a ground
station written in Python answers within that. MIN_RTO_S (20 ms) is the floor, so a loopback
link re-requests a lost item after some tens of milliseconds, not after ArduPilot's 1 s; RFC 6298's
1 s floor protects TCP's congestion window, which a lock-step item transfer does not have. The
ceiling `max_s` is `mission.retry_ms`: gcsd never waits longer than ArduPilot would.
Before the first sample RFC 6298 waits 1 s and ArduPilot always does; gcsd starts at 250 ms, the
item timeout the MAVLink mission specification suggests to ground stations, because MAVSDK counts
each of its own 0.5 s timeouts against the 5 tries it allows one item (a first item lost while the
vehicle waits 1 s costs it three of them); a slow radio is covered by the backlog term below.

**Backoff** (section 5.5): a timeout doubles the RTO until a new sample arrives, at most
MAX_BACKOFF (2) times and never beyond the ceiling. **Karn's rule** (section 3): a reply to a
request that was sent more than once gives no sample, since it cannot be told which copy it
answers (the caller simply does not call `sample()` then), and the backoff is kept until a reply
to a request sent once gives one.

Why at most x4, where RFC 6298 doubles up to 60 s: an item transfer is lock-step, one request in
flight, so retrying cannot congest the link; and the ground station's patience is per item:
MAVSDK abandons an upload after 5 sends of one item or 5 of its 0.5 s timeouts, so a vehicle
that backs off to a second loses the upload the link would have carried. Simulated (500 items,
20 % loss each way, MAVSDK's rules): the whole upload succeeds 7 % of the time with unlimited
doubling, 66 % with x16, 85-87 % with x4 or x8, which is the client's own limit (5 lost sends of
one item in 500). x4 still lets Karn's rule learn a round trip up to 4 RTOs, and the RTO is
already SRTT + 4 RTTVAR.

**The link's byte budget.** `timeout_s(queued_s)` adds the time the link needs to transmit what
is already queued ahead of the request (a channel's token-bucket backlog at its bandwidth) on top
of the RTO, and the caller adds ArduPilot's RADIO_STATUS slowdown too, so a 57 600 baud radio
whose buffer is full of telemetry is never asked again before the request could even have gone
out. Its own RTT samples already include the frames' transmission time at 5 760 bytes/s.

**Per peer.** `RttTable` keeps one estimator per key (channel index, sysid, compid), the most
recently used MAX_PEERS (16) of them, so a ground station's second upload starts with what its
first one measured.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Hashable

ALPHA = 1 / 8
BETA = 1 / 4
K = 4
GRANULARITY_S = 0.010
MIN_RTO_S = 0.020
INITIAL_RTO_S = 0.250
MAX_BACKOFF = 2  # doublings of the RTO on timeouts, x4 (see above)
MAX_PEERS = 16


class RttEstimator:
    """SRTT, RTTVAR and the RTO with backoff for one peer. All times in seconds."""

    __slots__ = ("backoff", "initial_s", "max_s", "min_s", "rttvar_s", "samples", "srtt_s")

    def __init__(self, initial_s: float = INITIAL_RTO_S, max_s: float | None = None,
                 min_s: float = MIN_RTO_S) -> None:
        self.max_s = initial_s if max_s is None else max_s
        self.initial_s = min(initial_s, self.max_s)
        self.min_s = min(min_s, self.max_s)
        self.srtt_s: float | None = None
        self.rttvar_s = 0.0
        self.backoff = 0
        self.samples = 0

    def sample(self, rtt_s: float) -> None:
        """A measured round trip (a reply to a request sent once); clears the backoff."""
        rtt_s = max(0.0, rtt_s)
        if self.srtt_s is None:
            self.srtt_s = rtt_s
            self.rttvar_s = rtt_s / 2
        else:
            self.rttvar_s = (1 - BETA) * self.rttvar_s + BETA * abs(self.srtt_s - rtt_s)
            self.srtt_s = (1 - ALPHA) * self.srtt_s + ALPHA * rtt_s
        self.backoff = 0
        self.samples += 1

    def timed_out(self) -> None:
        """No reply within the RTO: the next one is twice as long (at most x4, up to the ceiling)."""
        self.backoff = min(self.backoff + 1, MAX_BACKOFF)

    @property
    def base_rto_s(self) -> float:
        """The RTO without backoff."""
        if self.srtt_s is None:
            return self.initial_s
        rto = self.srtt_s + max(GRANULARITY_S, K * self.rttvar_s)
        return min(self.max_s, max(self.min_s, rto))

    @property
    def rto_s(self) -> float:
        return min(self.max_s, self.base_rto_s * (2 ** self.backoff))

    def timeout_s(self, queued_s: float = 0.0) -> float:
        """How long to wait for a reply to a request sent now behind `queued_s` of link backlog."""
        return self.rto_s + max(0.0, queued_s)


class RttTable:
    """One RttEstimator per peer key, the MAX_PEERS most recently used."""

    def __init__(self, initial_s: float = INITIAL_RTO_S, max_s: float | None = None, min_s: float = MIN_RTO_S,
                 max_peers: int = MAX_PEERS) -> None:
        self.initial_s, self.max_s, self.min_s = initial_s, max_s, min_s
        self.max_peers = max_peers
        self._peers: OrderedDict[Hashable, RttEstimator] = OrderedDict()

    def get(self, key: Hashable) -> RttEstimator:
        est = self._peers.get(key)
        if est is None:
            est = RttEstimator(self.initial_s, self.max_s, self.min_s)
            self._peers[key] = est
            while len(self._peers) > self.max_peers:
                self._peers.popitem(last=False)
        else:
            self._peers.move_to_end(key)
        return est

    def __len__(self) -> int:
        return len(self._peers)
