"""Rate caps on a channel's output (SPEC.md "Companion routing", `rate_limits`): pure, `now` passed in.

Per (message id, source system, source component), at most `hz` frames per second leave the
channel. Each source has a schedule, `next_s`: a frame at `now >= next_s` passes and moves the
schedule one period on; an earlier frame is dropped (and counted by the caller). The frame that
passes is always the one at hand, so a cap never delays or queues anything: the newest frame
wins. Moving the schedule by a period, not to `now + period`, keeps a source that sends faster
than the cap at the cap on average even when its frames arrive with jitter (a frame one
millisecond early is dropped, the next one passes and the schedule catches up); after a silence
longer than a period the schedule restarts at `now`, so no burst is owed.

States per source: none (first frame passes) -> scheduled (next_s). At most MAX_SOURCES are
tracked; beyond that the table is cleared (each source's next frame then passes: a bounded,
rare over-send rather than unbounded memory).
"""

from __future__ import annotations

from collections.abc import Mapping

MAX_SOURCES = 4096
SLACK_S = 1e-6  # float sums of periods (0.1 * 3 > 0.3) must not push a frame on schedule to the next slot


class RateCaps:
    """Message id -> Hz caps for one channel's output."""

    __slots__ = ("_next_s", "_period_s", "limited")

    def __init__(self, limits_hz: Mapping[int, float]) -> None:
        self._period_s = {msgid: 1.0 / hz for msgid, hz in limits_hz.items() if hz > 0}
        self._next_s: dict[int, float] = {}
        self.limited = 0  # frames dropped by a cap

    def __bool__(self) -> bool:
        return bool(self._period_s)

    def period_s(self, msgid: int) -> float | None:
        """The cap's period for a message id; None: not capped."""
        return self._period_s.get(msgid)

    def allow(self, msgid: int, sysid: int, compid: int, now: float) -> bool:
        period = self._period_s.get(msgid)
        return True if period is None else self.allow_key(msgid << 16 | sysid << 8 | compid, period, now)

    def allow_key(self, key: int, period: float, now: float) -> bool:
        """One frame of a capped message; `key` is msgid << 16 | sysid << 8 | compid."""
        schedule = self._next_s
        next_s = schedule.get(key)
        if next_s is not None and now < next_s - SLACK_S:
            self.limited += 1
            return False
        if next_s is None or now - next_s >= period:  # first frame, or silent for a period: restart
            next_s = now
        if len(schedule) >= MAX_SOURCES and key not in schedule:
            schedule.clear()
        schedule[key] = next_s + period
        return True
