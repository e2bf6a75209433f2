"""The one clock. Protocol code only ever sees `now` (monotonic seconds) passed in; this object
is where the asyncio layer gets it, and what tests replace."""

from __future__ import annotations

import time
from collections.abc import Callable


class Clock:
    def __init__(self, monotonic: Callable[[], float] = time.monotonic, wall: Callable[[], float] = time.time):
        self._monotonic = monotonic
        self._wall = wall
        self.boot_s = monotonic()

    def now(self) -> float:
        return self._monotonic()

    __call__ = now

    def wall(self) -> float:
        """Unix time in seconds (SYSTEM_TIME, signing timestamps)."""
        return self._wall()

    def since_boot(self, now: float) -> float:
        return now - self.boot_s
