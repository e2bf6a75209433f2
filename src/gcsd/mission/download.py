"""Mission downloads through a lossy link: what the vehicle does so that they finish.

A download is driven by the ground station: it asks for the count, then for each item, and gives
up after a few unanswered requests of one item (MAVSDK: 5 sends, 0.5 s apart, taking an item only
in sequence; MAVProxy re-requests after 2 s; QGroundControl likewise). Through 20 % loss each way
a request and its answer both arrive only 64 % of the time, so a 200-item MAVSDK download failed
one time in three. The vehicle cannot retry for the ground station, but where the link is lossy
(`lossy`: the share of the requester's frames missing from its MAVLink sequence, measured per
peer, is at least LOSSY over at least MIN_FRAMES frames) it makes its answers likelier to arrive:

- MISSION_COUNT goes COUNT_COPIES times (MAVProxy never asks for it again);
- the item asked for goes ITEM_COPIES times, and the WINDOW - 1 items after it once each, in
  order, right behind it: a ground station that has just taken the item it asked for takes the
  following ones if they arrive, so its progress no longer needs each of its requests to get
  through (MAVSDK takes an item that arrives in sequence, MAVProxy and QGroundControl any item
  they still lack; all ignore one they have);
- when a requester has sent nothing for REPUSH_S, the window from the highest item it asked for
  is sent again, at most MAX_REPUSH times in a row: a lost request is made up for without it
  (MAVSDK restarts its timeout on every item it receives, so it does not spend its retries
  meanwhile). Its MISSION_ACK, a new REQUEST_LIST or MAX_REPUSH silent rounds end it.

Every copy beyond the first answer is optional: the adapter sends it only when it would go out at
once (no reply queued, room in the link's byte budget), so a slow radio is never flooded by them
and they never push an owed reply out of the queue. Ground stations drop duplicates.
Bounded: MAX_REQUESTERS downloads followed (the least recent forgotten), WINDOW items per answer.
Pure: `now` in, what to send out; the transfer machine (transfer.py) turns seqs into messages.
"""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass

LOSSY = 0.05  # a link missing this share of a requester's frames is lossy
MIN_FRAMES = 10  # ...measured over at least this many frames
COUNT_COPIES = 3
ITEM_COPIES = 2
WINDOW = 8  # the item asked for and the ones after it
REPUSH_S = 0.3  # below MAVSDK's 0.5 s item timeout
MAX_REPUSH = 10
MAX_REQUESTERS = 8


def is_lossy(loss: float, frames: int) -> bool:
    return frames >= MIN_FRAMES and loss >= LOSSY


@dataclass(slots=True)
class _Download:
    channel: Hashable
    legacy: bool  # MISSION_REQUEST (float items) rather than MISSION_REQUEST_INT
    count: int
    top: int  # the highest seq asked for
    last_s: float  # when the requester was last heard, or the window last sent again
    repushes: int = 0


@dataclass(frozen=True, slots=True)
class Push:
    channel: Hashable
    node: tuple[int, int]
    legacy: bool
    seqs: range


class DownloadAssist:
    def __init__(self, window: int = WINDOW, repush_s: float = REPUSH_S, max_repush: int = MAX_REPUSH,
                 max_requesters: int = MAX_REQUESTERS) -> None:
        self.window = window
        self.repush_s = repush_s
        self.max_repush = max_repush
        self.max_requesters = max_requesters
        self._downloads: dict[tuple[int, int], _Download] = {}

    def requested(self, node: tuple[int, int], channel: Hashable, seq: int, count: int, legacy: bool,
                  now: float) -> range:
        """A request for `seq` on a lossy link: the items to send right behind it."""
        d = self._downloads.pop(node, None)
        if d is None or d.count != count or d.channel != channel:
            if len(self._downloads) >= self.max_requesters:
                del self._downloads[next(iter(self._downloads))]
            d = _Download(channel, legacy, count, seq, now)
        if seq > d.top:
            d.top, d.repushes = seq, 0
        d.last_s, d.legacy = now, legacy
        self._downloads[node] = d  # most recent last
        return range(seq + 1, min(count, seq + self.window))

    def finish(self, node: tuple[int, int]) -> None:
        """The requester is done (its MISSION_ACK) or starts again (REQUEST_LIST)."""
        self._downloads.pop(node, None)

    def channels(self) -> set[Hashable]:
        return {d.channel for d in self._downloads.values()}

    def next_deadline(self) -> float | None:
        return min((d.last_s + self.repush_s for d in self._downloads.values()), default=None)

    def tick(self, now: float) -> list[Push]:
        out = []
        for node, d in list(self._downloads.items()):
            if now < d.last_s + self.repush_s:
                continue
            if d.repushes >= self.max_repush:
                del self._downloads[node]
                continue
            d.repushes += 1
            d.last_s = now
            out.append(Push(d.channel, node, d.legacy, range(d.top, min(d.count, d.top + self.window))))
        return out
