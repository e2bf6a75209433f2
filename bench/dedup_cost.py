"""What loop protection (gcsd.routing.dedup.RecentFrames) costs per routed frame.

Run: ``python -m bench.dedup_cost`` (a few seconds, one core).

Frames: 44-byte MAVLink2 COMMAND_LONG frames from one source as the routing benchmark sends
them (bench/frames.py: a unique sequence number in the payload), each a distinct bytes object
made up front. The routing path does, per forwarded frame, one ``seen(raw, now)`` and one
``remember(raw, now)``; per frame that is only handled locally, one ``seen``. Timed: that work
for N frames at a given rate on a fake clock advancing 1/rate per frame (so the window holds
rate x LOOP_WINDOW_S frames at steady state, as in the daemon), against an empty loop over the
same frames; reported in nanoseconds per frame, best of 5 runs of 200 000 frames, after a
warm-up run that fills the window. Also the same with 267-byte frames (the largest unsigned). Each run gets new bytes objects
(made untimed), so every frame's hash is computed once in the timed loop, as in the daemon.
"""

from __future__ import annotations

import platform
import sys
import time

from gcsd.routing.dedup import LOOP_WINDOW_S, RecentFrames

N = 200_000


def frames(count: int, size: int) -> list[bytes]:
    head = bytes([0xFD, size - 12, 0, 0])
    return [head + i.to_bytes(4, "little") + bytes(size - 10) + b"\x12\x34" for i in range(count)]


def fresh(raws: list[bytes]) -> list[bytes]:
    return [bytes(bytearray(raw)) for raw in raws]


def run(template: list[bytes], rate_hz: float, forwarded: bool) -> float:
    recent = RecentFrames(LOOP_WINDOW_S)
    step = 1.0 / rate_hz
    seen, remember = recent.seen, recent.remember

    def once(t0: float) -> float:
        raws = fresh(template)  # new objects: their hashes are not cached yet, as in the daemon
        now = t0
        start = time.perf_counter()
        if forwarded:
            for raw in raws:
                if not seen(raw, now):
                    remember(raw, now)
                now += step
        else:
            for raw in raws:
                seen(raw, now)
                now += step
        return time.perf_counter() - start

    def empty() -> float:
        raws = fresh(template)
        now = 0.0
        start = time.perf_counter()
        for _raw in raws:
            now += step
        return time.perf_counter() - start

    once(0.0)  # warm-up: fills the window
    best = min(once(1000.0 + k * 100.0) for k in range(5))
    base = min(empty() for _ in range(5))
    return (best - base) / len(template) * 1e9


def main() -> int:
    print(f"# {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, Python {sys.version.split()[0]}, "
          f"{platform.processor() or platform.machine()}")
    for size in (44, 267):
        raws = frames(N, size)
        for rate in (1_000, 30_000):
            fwd = run(raws, rate, True)
            local = run(raws, rate, False)
            print(f"{size:3d}-byte frames at {rate:6d}/s (window holds {int(rate * LOOP_WINDOW_S)}): "
                  f"forwarded {fwd:5.0f} ns/frame, handled locally {local:5.0f} ns/frame")
    return 0


if __name__ == "__main__":
    sys.exit(main())
