"""Recently seen frames: a bounded, time-windowed set of frame bytes. Pure: every call takes `now`.

`RecentFrames(window_s)` answers "were these exact bytes remembered less than window_s ago?".
Keys are whole frames, header to signature: the sequence number is part of them, so a source
repeats a key only when its payload is unchanged and its sequence number has wrapped (256
frames later), and a signed frame never repeats (its timestamp rises).

States per key: absent -> remembered at t (`remember`) -> expired at t + window_s (absent again).
`seen(raw, now)` is true only for a remembered, unexpired key; it changes nothing, so a frame
that keeps coming back is still forgotten window_s after it was remembered.
Bound: at most `max_frames` keys; beyond it the oldest is forgotten first (the window shrinks
under a flood, `evicted` counts it) instead of memory growing. Expiry walks a FIFO of
(time, key) from its old end, every eighth of a window (and at once beyond max_frames):
O(1) amortised, no timer; `seen` compares times, so a key not yet swept is still expired.

Uses:
- Loop protection (ingress.py, on by default, LOOP_WINDOW_S): the ingress remembers every frame it
  forwards; the same bytes arriving again within the window can only be a copy of a frame
  gcsd already passed on (a forwarding loop, or a second path to the same place), so they
  are dropped and counted (`loop_dropped`), neither routed nor handled again. gcsd forwards
  byte-exact, so a frame circulating between two bridged instances is identical each round
  and dies at its first return. Frames that were only handled locally are never remembered,
  so nothing a ground station sends to gcsd alone is ever dropped.
- `routing.dedup_ms` and redundant link groups (SPEC "Companion routing"): every frame, with
  the window the configuration gives.

Why LOOP_WINDOW_S = 0.5 s: a loop's round trip must fit in it (loopback and LAN bridges take
well under a millisecond, a broker across the internet tens to a few hundred); and it stays
below one second so that a 1 Hz HEARTBEAT whose bytes repeat (unchanged payload, and a
sequence number that wrapped in step with it: exactly 256 x k frames a second from that
source) can never be taken for its own echo and lost.

Cost (bench/dedup_cost.py, bench/RESULTS.md): a lookup is one dict probe on the frame's bytes;
remembering adds a dict store, a deque append and the amortised expiry. Every routed frame pays
them, so the same class is also in C (gcsd.wire._speedups.RecentFrames, used when built).
"""

from __future__ import annotations

from collections import deque

from gcsd.wire import speedups

LOOP_WINDOW_S = 0.5
MAX_FRAMES = 65536  # 0.5 s of 130 000 frames/s, four times what one process routes
SWEEP_FRACTION = 0.125  # expired keys are swept out every eighth of a window


class RecentFramesPython:
    """The reference; `RecentFrames` is the compiled one when gcsd.wire._speedups is built (the unit
    tests run both, and compare them on random sequences)."""

    __slots__ = ("_at", "_order", "_sweep_at", "evicted", "max_frames", "window_s")

    def __init__(self, window_s: float, max_frames: int = MAX_FRAMES) -> None:
        if not 0 < window_s < float("inf") or max_frames < 1:  # NaN fails the comparison too
            raise ValueError("window_s must be > 0 and finite, and max_frames >= 1")
        self.window_s = float(window_s)
        self.max_frames = max_frames
        self._at: dict[bytes, float] = {}
        self._order: deque[tuple[float, bytes]] = deque()
        self.evicted = 0  # keys forgotten before their window ended, to stay within max_frames
        self._sweep_at = float("-inf")

    def __len__(self) -> int:
        return len(self._at)

    def seen(self, raw: bytes, now: float) -> bool:
        """These bytes were remembered less than window_s ago."""
        at = self._at.get(raw)
        return at is not None and now - at < self.window_s

    def remember(self, raw: bytes, now: float) -> None:
        """Remember these bytes from `now` (again, if they had expired)."""
        at = self._at
        at[raw] = now
        self._order.append((now, raw))
        if now >= self._sweep_at or len(at) > self.max_frames:
            self._expire(now)

    def _expire(self, now: float) -> None:
        """Forget what is older than the window (and the oldest beyond max_frames). Run every
        SWEEP_FRACTION of a window rather than per frame: `seen` compares times itself, so an
        expired key still held until the next sweep is never taken for a recent one."""
        at = self._at
        order = self._order
        horizon = now - self.window_s
        self._sweep_at = now + self.window_s * SWEEP_FRACTION
        while order and (order[0][0] <= horizon or len(at) > self.max_frames):
            t, key = order.popleft()
            if at.get(key) == t:
                del at[key]
                if t > horizon:
                    self.evicted += 1

    def check(self, raw: bytes, now: float) -> bool:
        """Deduplication in one call: True if these bytes were seen within the window (a
        duplicate, not remembered again); else they are remembered and False."""
        if self.seen(raw, now):
            return True
        self.remember(raw, now)
        return False


RecentFrames = speedups.compiled.RecentFrames if speedups.compiled is not None else RecentFramesPython
