"""The per-link deferred send scheduler (ArduPilot's GCS_MAVLINK::update_send), pure.

Three kinds of work, served in this order on every `run(now, send)`:

1. Special slots with their own interval, never slowed down: HEARTBEAT (1000 ms) and
   HIGH_LATENCY2 (a parameter list download is streamed by ParamService.pending instead).
2. Pushed one-shot messages (REQUEST_MESSAGE, home after a change...), lowest id first.
3. Ten buckets, each a set of message ids sharing one interval. The bucket due soonest is taken;
   its ids are sent one by one; only when all are out is the bucket rescheduled.

`send(msgid)` is supplied by the caller: it builds and writes the message and returns False when
the link has no room (byte budget spent). The pass stops there; the same message is retried on
the next pass. A message the vehicle cannot produce (no home yet) counts as sent.

Clocks advance by exactly one interval after a send (rates keep their phase) and snap to `now`
when more than one interval behind. The reschedule interval of a bucket is its interval plus
`slowdown_ms` (from RADIO_STATUS) times `slow_factor` (×4 while parameters, mission items or FTP
are streaming on this link), capped at 60 s.

Intervals are whole milliseconds, as in ArduPilot, so GET_MESSAGE_INTERVAL reports what is
really used. `set_interval` implements the bucket assignment of `set_ap_message_interval`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

NUM_BUCKETS = 10
MAX_INTERVAL_MS = 60_000
MIN_INTERVAL_MS = 1  # backstop; the real cap (SCHED_LOOP_RATE) is applied where requests are accepted


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


def _advance(last_s: float, interval_s: float, now: float) -> float:
    """Next due time keeping phase; snap to now when more than one interval behind."""
    nxt = last_s + interval_s
    if now - nxt > interval_s:
        return now
    return nxt
