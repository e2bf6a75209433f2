"""Write-behind of one state file: coalesced, off the event loop, atomic, flushed at a clean stop.

The policy lives in the source (a pure object, e.g. ParamService): `persist_deadline()` says
when the file is next due, `take_persist(now, force)` hands over the text to write (a snapshot
taken on the loop's thread, so it is consistent) and marks the source clean, `persist_done()`
and `persist_failed(error)` take the outcome. This adapter only does the I/O:

- `kick()` (the source's `on_dirty` hook, called on the loop's thread) arms one loop timer for
  the deadline, unless a timer is armed or a write is in flight (then `_written` re-arms).
- When the timer fires the text is taken and written by `write_atomic` (write, fsync, rename,
  fsync the directory) on this file's own worker thread: the loop never waits for the disk.
  At most one write per file is in flight, so writes land in order.
- `sync()` (SIGHUP): cancel the timer, wait for the write in flight, write what is still
  dirty, synchronously; later changes are written behind as before.
- `flush()` at a clean stop: `sync()`, then no more writes, and the worker thread stops.

With no running loop (a node built outside asyncio: the unit-test harness, a script) there is
nothing to block: `kick` writes at once, synchronously, when the file is due, and otherwise
leaves it to the next `kick` or to `flush`. Errors never escape: a failed write goes to the
source, which retries; an exception in the timer or completion callback (the source's own
code) is counted by the daemon's boundary as "persist:<file>" and the next `kick` re-arms.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
from collections.abc import Callable
from pathlib import Path
from typing import Protocol

import structlog

from gcsd.atomic import write_atomic
from gcsd.boundary import ErrorCounts

log = structlog.get_logger("gcsd.persist")


class PersistSource(Protocol):
    def persist_deadline(self) -> float | None: ...
    def take_persist(self, now: float, force: bool = False) -> str | None: ...
    def persist_done(self) -> None: ...
    def persist_failed(self, error: str) -> None: ...


class WriteBehind:
    def __init__(self, path: Path, source: PersistSource, now: Callable[[], float],
                 write: Callable[[Path, str], None] | None = None, errors: ErrorCounts | None = None) -> None:
        self.path = path
        self.errors = errors if errors is not None else ErrorCounts()
        self._component = f"persist:{path.name}" if path is not None else "persist"
        self.source = source
        self._now = now
        self._write = write or write_atomic
        self._loop: asyncio.AbstractEventLoop | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._inflight: concurrent.futures.Future | None = None
        self._executor: concurrent.futures.ThreadPoolExecutor | None = None
        self._closed = False
        self.writes = 0  # files written

    def kick(self) -> None:
        """The source is dirty: make sure a write happens at its deadline."""
        if self._closed or self._timer is not None or self._inflight is not None:
            return
        deadline = self.source.persist_deadline()
        if deadline is None:
            return
        try:
            self._loop = asyncio.get_running_loop()
        except RuntimeError:  # no loop, nothing to block: write now if due
            self._write_now(self.source.take_persist(self._now()))
            return
        self._timer = self._loop.call_later(max(0.0, deadline - self._now()), self._due)

    def _due(self) -> None:
        self._timer = None
        with self.errors.guard(self._component, self._now(), path=str(self.path)):
            self._start_write()

    def _start_write(self) -> None:
        text = self.source.take_persist(self._now())
        if text is None:  # woke a little early, or nothing left
            self.kick()
            return
        if self._executor is None:
            self._executor = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="gcsd-persist")
        self._inflight = self._executor.submit(self._write, self.path, text)
        loop = self._loop
        self._inflight.add_done_callback(lambda fut: _call_soon(loop, self._written, fut))

    def _written(self, fut: concurrent.futures.Future) -> None:
        if fut is not self._inflight:  # flush() already took care of it
            return
        self._inflight = None
        with self.errors.guard(self._component, self._now(), path=str(self.path)):
            self._outcome(fut.exception())
            self.kick()

    def _outcome(self, error: BaseException | None) -> None:
        if error is None:
            self.writes += 1
            self.source.persist_done()
        else:
            self.source.persist_failed(str(error))

    def sync(self) -> None:
        """Everything dirty now is on disk when this returns, and the write-behind goes on
        (SIGHUP: nothing acknowledged waits on a timer while the configuration is re-read)."""
        if self._closed:
            return
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self._inflight is not None:
            inflight, self._inflight = self._inflight, None
            self._outcome(inflight.exception())  # waits for the write in flight
        self._write_now(self.source.take_persist(self._now(), force=True))

    def flush(self) -> None:
        """A clean stop: everything still dirty is on disk when this returns."""
        self.sync()
        self._closed = True
        if self._executor is not None:
            self._executor.shutdown(wait=True)
            self._executor = None

    def _write_now(self, text: str | None) -> None:
        if text is None:
            return
        try:
            self._write(self.path, text)
        except Exception as exc:  # noqa: BLE001 - the source logs and reports it
            self._outcome(exc)
        else:
            self._outcome(None)


def _call_soon(loop: asyncio.AbstractEventLoop | None, fn, arg) -> None:
    """From the worker thread: run fn(arg) on the loop, unless the loop is gone (a stop)."""
    if loop is None:
        return
    try:
        loop.call_soon_threadsafe(fn, arg)
    except RuntimeError:  # the loop is closed; flush() handled the outcome
        pass
