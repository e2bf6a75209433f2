"""Mission downloads: the answers to a ground station's download, and what the vehicle does so
that a download through a lossy link finishes. Pure: `now` in, what to send out.

**The answers** (`Downloads`, one per mission type, asked by the transfer machine, transfer.py,
which refuses a download while an upload is in progress): downloads keep no transfer state, as
in ArduPilot: REQUEST_LIST -> MISSION_COUNT; REQUEST_INT -> MISSION_ITEM_INT (out of range ->
MISSION_COUNT then INVALID_SEQUENCE); legacy REQUEST -> MISSION_ITEM with a once-per-list
warning. Requests may be pipelined and out of order; each is answered on its own. An item the
same ground station asks for again since its REQUEST_LIST is sent twice* (the request proves a
reply was lost: MAVSDK abandons a whole download after 5 tries of one item, so on a lossy link
the second copy is what lets it finish; clients ignore the duplicate). The GCS's final
MISSION_ACK of a download needs no answer. This bookkeeping is kept for MAX_REQUESTERS ground
stations (the least recent forgotten). (* where gcsd improves on ArduPilot.)

**A lossy link.** A download is driven by the ground station: it asks for the count, then for
each item, and gives
up after a few unanswered requests of one item (MAVSDK: 5 sends, 0.5 s apart, taking an item only
in sequence; MAVProxy re-requests after 2 s; QGroundControl likewise). Through 20 % loss each way
a request and its answer both arrive only 64 % of the time, so a 200-item MAVSDK download failed
one time in three. The vehicle cannot retry for the ground station, but where the link is lossy
(`lossy`: the share of the requester's frames missing from its MAVLink sequence, measured per
peer, is at least LOSSY over at least MIN_FRAMES frames) it makes its answers likelier to arrive
(`DownloadAssist`):

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

Every copy beyond the first answer is optional (`Send(optional=True)`): the adapter sends it only
when it would go out at once (no reply queued, room in the link's byte budget), so a slow radio is
never flooded by them and they never push an owed reply out of the queue. Ground stations drop
duplicates. Bounded: MAX_REQUESTERS downloads followed (the least recent forgotten), WINDOW items
per answer.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission.effects import Origin, Output, Send, Text
from gcsd.vehicle.mission.items import MissionItem, item_float_message, item_int_message
from gcsd.vehicle.mission.stores import PlanStore

LOSSY = 0.05  # a link missing this share of a requester's frames is lossy
MIN_FRAMES = 10  # ...measured over at least this many frames
COUNT_COPIES = 3
ITEM_COPIES = 2
WINDOW = 8  # the item asked for and the ones after it
REPUSH_S = 0.3  # below MAVSDK's 0.5 s item timeout
MAX_REPUSH = 10
MAX_REQUESTERS = 8  # downloads followed, and requesters whose repeated requests are remembered
REPEAT_COPIES = 2  # an item asked for again is sent twice
LEGACY_REQUEST_TEXT = "got MISSION_REQUEST; use MISSION_REQUEST_INT!"


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


class Downloads:
    """The answers to downloads of one store's plan (see the module's docstring)."""

    def __init__(self, store: PlanStore, lossy: Callable[[Origin], bool] = lambda origin: False) -> None:
        self.store = store
        self.lossy = lossy
        self.assist = DownloadAssist()
        self._warned: set[tuple[int, int]] = set()  # told to use MISSION_REQUEST_INT, this list
        self._answered: dict[tuple[int, int], set[int]] = {}  # per requester, since its REQUEST_LIST

    def request_list(self, origin: Origin, now: float) -> list[Output]:
        self._warned.discard(origin.node)
        self._answered.pop(origin.node, None)
        self.assist.finish(origin.node)
        count = self.count(origin)
        if not self.lossy(origin):
            return [count]
        return [count] + [Send(count.channel, count.msg, True)] * (COUNT_COPIES - 1)

    def request(self, origin: Origin, seq: int, legacy: bool, now: float) -> list[Output]:
        item = self.store.item(seq)
        if item is None:
            return [self.count(origin), Send(origin.channel, M.MAVLink_mission_ack_message(
                *origin.node, M.MAV_MISSION_INVALID_SEQUENCE, self.store.mission_type))]
        copies = REPEAT_COPIES if self._asked_before(origin.node, seq) else 1
        out: list[Output] = []
        if legacy and origin.node not in self._warned:
            if len(self._warned) >= MAX_REQUESTERS:
                self._warned.clear()
            self._warned.add(origin.node)
            out.append(Text(M.MAV_SEVERITY_WARNING, LEGACY_REQUEST_TEXT, origin.channel))
        answer = self._item_message(seq, item, origin.node, legacy)
        out += [Send(origin.channel, answer)] * copies
        if self.lossy(origin):
            out += [Send(origin.channel, answer, True)] * max(0, ITEM_COPIES - copies)
            ahead = self.assist.requested(origin.node, origin.channel, seq, self.store.count(), legacy, now)
            out += self._pushed(origin.channel, origin.node, legacy, ahead)
        return out

    def finish(self, node: tuple[int, int]) -> None:
        """The requester's MISSION_ACK: its download is over."""
        self.assist.finish(node)

    def next_deadline(self) -> float | None:
        return self.assist.next_deadline()

    def tick(self, now: float) -> list[Output]:
        out: list[Output] = []
        for push in self.assist.tick(now):
            out += self._pushed(push.channel, push.node, push.legacy, push.seqs)
        return out

    def count(self, origin: Origin) -> Send:
        count = M.MAVLink_mission_count_message(*origin.node, self.store.count(), self.store.mission_type)
        return Send(origin.channel, count)

    def _item_message(self, seq: int, item: MissionItem, target: tuple[int, int], legacy: bool):
        if legacy:
            return item_float_message(item, seq, self.store.mission_type, target)
        return item_int_message(item, seq, self.store.mission_type, target)

    def _pushed(self, channel: Hashable, target: tuple[int, int], legacy: bool, seqs: range) -> list[Output]:
        """Items sent unasked to a download on a lossy link: optional copies."""
        out: list[Output] = []
        for seq in seqs:
            item = self.store.item(seq)
            if item is not None:
                out.append(Send(channel, self._item_message(seq, item, target, legacy), True))
        return out

    def _asked_before(self, node: tuple[int, int], seq: int) -> bool:
        """Whether this requester already asked for seq in this download (then it lost a reply)."""
        answered = self._answered.pop(node, None)
        if answered is None:
            answered = set()
            if len(self._answered) >= MAX_REQUESTERS:
                del self._answered[next(iter(self._answered))]
        self._answered[node] = answered  # most recent last
        if seq in answered:
            return True
        answered.add(seq)
        return False
