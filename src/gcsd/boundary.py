"""Error boundaries: no exception in one part of the daemon stops a channel or the daemon.

Every part that runs code a peer can steer or that we do not own runs inside a boundary: each
message handler and command handler, each telemetry producer, each service's timer
(`pending`), the autopilot and simulation step (or an embedding program's backend), the send
pass of a node, the receive path of a frame (signing check, admission, routing, handling), the
MQTT link's message callback, the daemon's side tasks (stats, signing timestamp) and the
write-behind's timer and completion callbacks. When one raises, the boundary

- counts it under the part's component name ("handler:PARAM_SET", "producer:SYS_STATUS",
  "service:MissionService", "sim", "backend", ...), shown by `gcsd status` (`errors`);
- logs the traceback, rate-limited: the first failure of a component at once, then at most one
  line per LOG_INTERVAL_S per component, saying how many were not logged in between;
- returns, so the caller skips that part for this turn (a producer's message is not sent, a
  handler's message gets no further processing) and carries on with everything else.

One mechanism, two spellings: `with errors.guard(component, now, **context):` around a block,
or, on the per-frame hot paths where a `with` costs a call, `except Exception:
errors.failed(component, now, ...)`. The cost of a `try` that does not raise is nothing
measurable in CPython 3.11+ (zero-cost exception tables).
"""

from __future__ import annotations

import structlog

log = structlog.get_logger("gcsd.errors")

LOG_INTERVAL_S = 10.0


class ErrorCounts:
    """Per-component exception counters and their rate-limited log (one per daemon)."""

    def __init__(self) -> None:
        self.counts: dict[str, int] = {}
        self._logged_s: dict[str, float] = {}
        self._unlogged: dict[str, int] = {}

    def failed(self, component: str, now: float, **context) -> None:
        """Call from an `except Exception:` block: counts the failure and maybe logs its traceback."""
        self.counts[component] = self.counts.get(component, 0) + 1
        last = self._logged_s.get(component)
        if last is not None and now - last < LOG_INTERVAL_S:
            self._unlogged[component] = self._unlogged.get(component, 0) + 1
            return
        self._logged_s[component] = now
        log.exception("component_failed", component=component,
                      not_logged_since_last=self._unlogged.pop(component, 0), **context)

    def guard(self, component: str, now: float, **context) -> _Guard:
        """A block whose exception (not BaseException: cancellation goes through) is counted and
        logged as `failed` does, then swallowed."""
        return _Guard(self, component, now, context)

    def total(self) -> int:
        return sum(self.counts.values())

    def snapshot(self) -> dict[str, int]:
        return dict(sorted(self.counts.items()))


class _Guard:
    __slots__ = ("component", "context", "errors", "now")

    def __init__(self, errors: ErrorCounts, component: str, now: float, context: dict) -> None:
        self.errors, self.component, self.now, self.context = errors, component, now, context

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind, exc, tb) -> bool:
        if kind is None or not issubclass(kind, Exception):
            return False
        self.errors.failed(self.component, self.now, **self.context)  # log.exception sees exc_info
        return True
