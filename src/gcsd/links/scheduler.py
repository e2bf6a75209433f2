"""The per-link deferred send scheduler (ArduPilot's GCS_MAVLINK::update_send), pure, and the
services' share of a link's byte budget (ServiceShare).

Three kinds of work, served in this order on every `run(now, send)`:

1. Special slots with their own interval, never slowed down: HEARTBEAT (1000 ms) and
   HIGH_LATENCY2 (a parameter list download is streamed by ParamService.pending instead).
2. Pushed one-shot messages (REQUEST_MESSAGE, home after a change...), lowest id first.
3. Ten buckets, each a set of message ids sharing one interval. The bucket due soonest is taken;
   its ids are sent one by one; only when all are out is the bucket rescheduled.

`run_urgent` does 1 and 2, `run_streams` does 3 (`run` is both): the node's send pass puts the
services' turn between them (below).

`send(msgid)` is supplied by the caller: it builds and writes the message and returns False when
the link has no room (byte budget spent). The pass stops there; the same message is retried on
the next pass. A message the vehicle cannot produce (no home yet) counts as sent.

Clocks advance by exactly one interval after a send (rates keep their phase) and snap to `now`
when more than one interval behind. The reschedule interval of a bucket is its interval plus
`slowdown_ms` (from RADIO_STATUS) times `slow_factor` (×4 while parameters, mission items or FTP
are streaming on this link), capped at 60 s.

Intervals are whole milliseconds, as in ArduPilot, so GET_MESSAGE_INTERVAL reports what is
really used. `set_interval` implements the bucket assignment of `set_ap_message_interval`.

The pass (VehicleNode.send_pass), in order of priority:

1. replies queued in the outbox (ACKs, PARAM_VALUE answers, mission items: owed, client-paced);
   while some remain, 2 and 3 wait for the next pass;
2. `run_urgent`: HEARTBEAT and pushed messages;
3. STATUSTEXT, then each service's `pending` (a parameter list, FTP replies and bursts, log
   data, mission requests and timers);
4. `run_streams`: the buckets.

1 and 3 are the services' turn. A link with a byte budget (`bandwidth`; a serial channel's is
baud // 10) also has a ServiceShare: while streams are due (`streams_due`), the services' turn
may spend only SERVICE_SHARE (2/3) of the budget's rate, and the streams keep the rest; while a
reply or a service waits for the budget to refill within its share (a whole frame, say), the
streams hold back for that pass (as ArduPilot reserves room for PARAM_VALUE). With no stream due
the services may use the whole budget, and with no service waiting the streams do: on a link
the streams alone fill (the copter's defaults want ~2 000 B/s, a 9 600-baud link has 960) a
parameter list, FTP, mission items and STATUSTEXT still get through, while the streams (slowed
×4 during a list, a mission upload or FTP, as in ArduPilot) keep over a quarter of it
(bench/slow_link.py).
ArduPilot orders it alike: the NEXT_PARAM special slot (queued parameter replies, then ~30 % of
the bandwidth for a list) ahead of the pushed messages and the buckets, FTP on its own thread
pacing bursts to a third of the link. A link without a budget has no share: the services simply
go before the buckets.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from gcsd.links.outbox import TokenBucket

NUM_BUCKETS = 10
MAX_INTERVAL_MS = 60_000
MIN_INTERVAL_MS = 1  # backstop; the real cap (SCHED_LOOP_RATE) is applied where requests are accepted
SERVICE_SHARE = 2 / 3  # of a link's byte budget, guaranteed to the services while the streams are due
HOLD_MAX_S = 1.0  # the streams hold back for a waiting service at most this long without it sending


@dataclass(slots=True)
class _Bucket:
    interval_ms: int = 0  # 0: empty
    ids: set[int] = field(default_factory=set)
    last_sent_s: float = 0.0


@dataclass(slots=True)
class _Special:
    interval_ms: int
    next_due_s: float


class SendScheduler:
    def __init__(self, now: float, special_ids: tuple[int, ...] = ()) -> None:
        self._buckets = [_Bucket() for _ in range(NUM_BUCKETS)]
        self._bucket_of: dict[int, int] = {}
        self._specials: dict[int, _Special] = {}
        self._special_ids = frozenset(special_ids)
        self._pushed: set[int] = set()
        self._sending: list[int] = []
        self._sending_bucket: int | None = None
        self.slowdown_ms = 0
        self.slow_factor = 1

    # --- intervals -------------------------------------------------------------------------
    def set_interval(self, msgid: int, interval_ms: int, now: float) -> None:
        """Schedule msgid every interval_ms (0 removes it)."""
        if interval_ms > 0:
            interval_ms = min(max(interval_ms, MIN_INTERVAL_MS), MAX_INTERVAL_MS)
        if msgid in self._special_ids:
            if interval_ms <= 0:
                self._specials.pop(msgid, None)
            else:
                special = self._specials.get(msgid)
                if special is None:
                    self._specials[msgid] = _Special(interval_ms, now)
                else:
                    special.interval_ms = interval_ms
                    # a shorter interval applies now, not after the old, longer wait
                    special.next_due_s = min(special.next_due_s, now + interval_ms / 1000.0)
            return
        current = self._bucket_of.get(msgid)
        if current is not None and self._buckets[current].interval_ms == interval_ms:
            return
        if current is not None:
            self._remove(msgid, current)
        if interval_ms <= 0:
            return
        exact = nearest = empty = None
        for i, bucket in enumerate(self._buckets):
            if bucket.interval_ms == 0:
                if empty is None:
                    empty = i
                continue
            if bucket.interval_ms == interval_ms:
                exact = i
            if nearest is None or abs(bucket.interval_ms - interval_ms) < abs(
                self._buckets[nearest].interval_ms - interval_ms
            ):
                nearest = i
        if exact is not None:
            target = exact
        elif empty is not None:
            target = empty
            self._buckets[target].interval_ms = interval_ms
            self._buckets[target].last_sent_s = now
        else:
            target = nearest  # ten intervals in use: join the nearest, as ArduPilot does
        self._buckets[target].ids.add(msgid)
        self._bucket_of[msgid] = target

    def _remove(self, msgid: int, index: int) -> None:
        bucket = self._buckets[index]
        bucket.ids.discard(msgid)
        del self._bucket_of[msgid]
        if not bucket.ids:
            bucket.interval_ms = 0
        if index == self._sending_bucket and msgid in self._sending:
            self._sending.remove(msgid)

    def interval_ms(self, msgid: int) -> int | None:
        """The interval in use for msgid, or None when it is not scheduled."""
        special = self._specials.get(msgid)
        if special is not None:
            return special.interval_ms
        index = self._bucket_of.get(msgid)
        return None if index is None else self._buckets[index].interval_ms

    # --- one-shots -------------------------------------------------------------------------
    def push(self, msgid: int) -> None:
        self._pushed.add(msgid)

    # --- the send pass ---------------------------------------------------------------------
    def _reschedule_ms(self, bucket: _Bucket) -> float:
        return min(bucket.interval_ms + self.slowdown_ms, MAX_INTERVAL_MS) * self.slow_factor

    def run(self, now: float, send: Callable[[int], bool]) -> bool:
        """Send what is due. Returns False if the pass stopped because the link was full."""
        return self.run_urgent(now, send) and self.run_streams(now, send)

    def run_urgent(self, now: float, send: Callable[[int], bool]) -> bool:
        """The special slots and the pushed one-shots (what goes ahead of the services' turn)."""
        for msgid, special in self._specials.items():
            if now >= special.next_due_s:
                if not send(msgid):
                    return False
                special.next_due_s = _advance(special.next_due_s, special.interval_ms / 1000.0, now)
        while self._pushed:
            msgid = min(self._pushed)
            if not send(msgid):
                return False
            self._pushed.discard(msgid)
        return True

    def streams_due(self, now: float) -> bool:
        """A bucket is due, or half sent: the streams want the link now."""
        if self._sending:
            return True
        return any(b.ids and b.last_sent_s + self._reschedule_ms(b) / 1000.0 <= now for b in self._buckets)

    def run_streams(self, now: float, send: Callable[[int], bool]) -> bool:
        """The buckets that are due; False if the link filled up before they were all sent."""
        while True:
            if not self._sending and not self._start_next_bucket(now):
                return True
            while self._sending:
                if not send(self._sending[0]):
                    return False
                self._sending.pop(0)
            self._finish_bucket(now)

    def _start_next_bucket(self, now: float) -> bool:
        best, best_due = None, None
        for i, bucket in enumerate(self._buckets):
            if not bucket.ids:
                continue
            due = bucket.last_sent_s + self._reschedule_ms(bucket) / 1000.0
            if best_due is None or due < best_due:
                best, best_due = i, due
        if best is None or best_due > now:
            return False
        self._sending_bucket = best
        self._sending = sorted(self._buckets[best].ids)
        return True

    def _finish_bucket(self, now: float) -> None:
        index = self._sending_bucket
        self._sending_bucket = None
        if index is None:
            return
        bucket = self._buckets[index]
        if bucket.ids:
            bucket.last_sent_s = _advance(bucket.last_sent_s, self._reschedule_ms(bucket) / 1000.0, now)

    def next_deadline(self, now: float) -> float | None:
        """When `run` next has something to do (None: nothing scheduled)."""
        if self._pushed or self._sending:
            return now
        deadlines = [s.next_due_s for s in self._specials.values()]
        deadlines += [
            b.last_sent_s + self._reschedule_ms(b) / 1000.0 for b in self._buckets if b.ids
        ]
        return min(deadlines) if deadlines else None


class ServiceShare:
    """The services' guaranteed share of one link's byte budget (a link with a `bandwidth`).

    A bucket filling at SERVICE_SHARE of the link's rate, twice as deep as the link's (so a
    reply or two of a few dozen bytes do not leave it short of the whole frame a reply waits
    for: the link's budget paces those; the share paces a sustained transfer). During the
    services' turn of every pass the outbox charges it with what the services send (`Outbox.share`;
    never below empty) and, when the streams are due (`begin(enforced=True)`), asks it as well
    as the link's budget: a service may send while its share has room. When the share has room
    but the link has not, the service is `waiting` and the streams hold back for this pass, so
    owed traffic of a whole frame is not nibbled away by 40-byte stream messages (an optional
    copy, skipped when there is no room, asks `Outbox.fits_now` and waits for nothing); when
    the share is spent, the streams have the link. A hold lasts HOLD_MAX_S at most without a
    service sending (`holds_streams`): forwarded frames, which the streams do not control, may
    keep the link short of a whole frame, and then the streams go on. Under contention the
    services get SERVICE_SHARE of the budget and the streams the rest; with no stream due the
    services may use all of it, and with no service waiting the streams do.
    """

    def __init__(self, rate_bps: float, link_capacity: float, now: float) -> None:
        self.bucket = TokenBucket(rate_bps * SERVICE_SHARE, now)
        self.bucket.capacity = self.bucket.tokens = 2.0 * link_capacity
        self.enforced = False
        self.waiting = False
        self._held_since_s: float | None = None  # streams held back, and no service sent, since

    def begin(self, enforced: bool) -> None:
        """A new services' turn: limited by the share when `enforced` (the streams are due)."""
        self.enforced = enforced
        self.waiting = False

    def admits(self, nbytes: int, link_tokens: float, link_capacity: float, now: float, waits: bool = True) -> bool:
        """May nbytes go now? `link_tokens`: what the link's budget holds at `now`; `waits`: the
        sender will wait for room (False: an optional copy, skipped when there is none)."""
        if not self.enforced:
            return link_tokens >= nbytes
        if self.bucket.wait_s(nbytes, now) > 0.0:
            return False  # the share is spent: the streams' turn
        if link_tokens >= nbytes:
            return True
        if waits and nbytes <= link_capacity:
            self.waiting = True  # owed traffic waits for the link to refill: the streams hold back
        return False

    def wait_s(self, nbytes: int, now: float) -> float:
        return self.bucket.wait_s(nbytes, now) if self.enforced else 0.0

    def charge(self, nbytes: int, now: float) -> None:
        self.bucket.charge(nbytes, now)
        self._held_since_s = None  # a service sent: the hold did its work

    def holds_streams(self, now: float) -> bool:
        """Do the streams hold back in this pass? While a service waits within its share, for at
        most HOLD_MAX_S on end without one sending (something the streams do not control, such
        as forwarded frames, may be keeping the link's budget short of the frame it waits for)."""
        if not self.waiting:
            self._held_since_s = None
            return False
        if self._held_since_s is None:
            self._held_since_s = now
        return now - self._held_since_s < HOLD_MAX_S


def _advance(last_s: float, interval_s: float, now: float) -> float:
    """Next due time keeping phase; snap to now when more than one interval behind."""
    nxt = last_s + interval_s
    if now - nxt > interval_s:
        return now
    return nxt
