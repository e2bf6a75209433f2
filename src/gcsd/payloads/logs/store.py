"""The flight-log directory: `NNNNNNNN.BIN` files, numbered in the order they were started.

- `entries()`: the logs, oldest first, as `LogEntry(id, name, size, time_utc)` with ids 1..N
  (the LOG_ENTRY ids) and `time_utc` the log's start (a finished log's mtime is set to its
  start when it is closed; a log being written reports the start it was created with).
- `create(wall_s)`: rotate, then open the next number for writing. Rotation deletes the oldest
  finished logs while there are `max_files` or more, or while the filesystem has less than
  `min_free_mb` free; a log that is open for writing is never deleted.
- `LogFile`: one log being written. `write_at(offset, data)` (pwrite, capture) and
  `append(data)` (the simulated log) go to the page cache, microseconds each, on the caller's
  thread; `room_ok()` says whether min_free_mb still holds (checked every CHECK_EVERY_BYTES);
  `finish()` fsyncs, closes and stamps the start time: it blocks, so the service runs it on a
  worker thread (`finish_off_loop`).
- `reopen(name, start)`: a finished log opened for writing again.
- `read(name, offset, count)`: one bounded pread (LOG_DATA chunks, at most 90 bytes).
- `erase(keep)`: every log except the ones open for writing (LOG_ERASE).

Nothing here raises for a peer's request: a missing file reads as b"" (the transfer ends).
"""

from __future__ import annotations

import asyncio
import os
import re
import shutil
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import structlog

log = structlog.get_logger("gcsd.payloads.logs")

NAME = re.compile(r"([0-9]{8})\.BIN")
CHECK_EVERY_BYTES = 1 << 20
READ_MAX = 4096


@dataclass(frozen=True, slots=True)
class LogEntry:
    id: int
    name: str
    size: int
    time_utc: int


def disk_free_bytes(path: Path) -> int:
    return shutil.disk_usage(path).free


class LogFile:
    def __init__(self, store: LogStore, name: str, fd: int, start_wall_s: float) -> None:
        self.store = store
        self.name = name
        self.path = store.directory / name
        self.fd = fd
        self.start_wall_s = start_wall_s
        self.size = 0
        self._unchecked = 0
        self.closed = False

    def write_at(self, offset: int, data: bytes) -> None:
        os.pwrite(self.fd, data, offset)
        self.size = max(self.size, offset + len(data))
        self._unchecked += len(data)

    def append(self, data: bytes) -> None:
        self.write_at(self.size, data)

    def room_ok(self) -> bool:
        """min_free_mb still holds (rotating older logs if needed); checked once per MiB written."""
        if self._unchecked < CHECK_EVERY_BYTES:
            return True
        self._unchecked = 0
        return self.store.make_room()

    def finish(self) -> None:
        if self.closed:
            return
        self.closed = True
        try:
            os.fsync(self.fd)
        finally:
            os.close(self.fd)
        os.utime(self.path, (self.start_wall_s, self.start_wall_s))
        self.store.closed(self)


class LogStore:
    def __init__(self, directory: Path, max_files: int, min_free_mb: int,
                 free_bytes: Callable[[Path], int] = disk_free_bytes) -> None:
        self.directory = Path(directory)
        self.max_files = max_files
        self.min_free_bytes = min_free_mb * 1024 * 1024
        self._free_bytes = free_bytes
        self._open: dict[str, LogFile] = {}
        self._lock = threading.Lock()  # finish() runs on a worker thread
        self.deleted = 0

    def ensure(self) -> None:
        self.directory.mkdir(parents=True, exist_ok=True)

    def _names(self) -> list[str]:
        try:
            with os.scandir(self.directory) as it:
                return sorted(e.name for e in it if NAME.fullmatch(e.name) and e.is_file(follow_symlinks=False))
        except OSError:
            return []

    def entries(self) -> list[LogEntry]:
        out = []
        with self._lock:
            open_now = dict(self._open)
        for name in self._names():
            try:
                st = os.stat(self.directory / name)
            except OSError:
                continue
            live = open_now.get(name)
            start = live.start_wall_s if live is not None else st.st_mtime
            out.append(LogEntry(len(out) + 1, name, st.st_size, max(0, int(start))))
        return out

    def is_open(self, name: str) -> bool:
        with self._lock:
            return name in self._open

    def create(self, wall_s: float) -> LogFile:
        self.ensure()
        names = self._names()
        number = int(NAME.fullmatch(names[-1])[1]) + 1 if names else 1
        self._rotate(names, reserve=1)
        name = f"{number:08d}.BIN"
        fd = os.open(self.directory / name, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o644)
        f = LogFile(self, name, fd, wall_s)
        with self._lock:
            self._open[name] = f
        log.info("flight_log_started", file=str(f.path))
        return f

    def reopen(self, name: str, start_wall_s: float) -> LogFile | None:
        """A finished log written to again (a captured stream that resumed after a silence)."""
        if not NAME.fullmatch(name):
            return None
        path = self.directory / name
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CLOEXEC | os.O_NOFOLLOW)
        except OSError:
            return None
        st = os.fstat(fd)
        f = LogFile(self, name, fd, start_wall_s)
        f.size = st.st_size
        with self._lock:
            self._open[name] = f
        return f

    def make_room(self) -> bool:
        """Delete the oldest finished logs while below min_free_mb; False if it still does not hold."""
        self._rotate(self._names(), reserve=0)
        return self._free_bytes(self.directory) >= self.min_free_bytes

    def _rotate(self, names: list[str], reserve: int) -> None:
        with self._lock:
            deletable = [n for n in names if n not in self._open]
        count = len(names)
        while deletable and (count + reserve > self.max_files or self._free_bytes(self.directory) < self.min_free_bytes):
            victim = deletable.pop(0)
            try:
                (self.directory / victim).unlink()
                self.deleted += 1
                log.info("flight_log_rotated", file=victim)
            except OSError as exc:
                log.error("flight_log_delete_failed", file=victim, error=str(exc))
            count -= 1
            names.remove(victim)

    def erase(self) -> int:
        """LOG_ERASE: every log that is not being written."""
        removed = 0
        for name in self._names():
            if self.is_open(name):
                continue
            try:
                (self.directory / name).unlink()
                removed += 1
            except OSError as exc:
                log.error("flight_log_delete_failed", file=name, error=str(exc))
        return removed

    def read(self, name: str, offset: int, count: int) -> bytes:
        try:
            fd = os.open(self.directory / name, os.O_RDONLY | os.O_CLOEXEC)
        except OSError:
            return b""
        try:
            return os.pread(fd, min(count, READ_MAX), offset)
        except OSError:
            return b""
        finally:
            os.close(fd)

    def closed(self, f: LogFile) -> None:
        with self._lock:
            if self._open.get(f.name) is f:  # not a reopened successor
                del self._open[f.name]
        log.info("flight_log_finished", file=str(f.path), size=f.size)


def finish_off_loop(f: LogFile) -> None:
    """fsync and close a finished log on a worker thread when a loop runs, else now."""
    try:
        loop = asyncio.get_running_loop()
    except RuntimeError:
        _finish_logged(f)
        return
    loop.run_in_executor(None, _finish_logged, f)


def _finish_logged(f: LogFile) -> None:
    try:
        f.finish()
    except OSError as exc:
        log.error("flight_log_close_failed", file=str(f.path), error=str(exc))
