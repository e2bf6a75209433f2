"""Telemetry logs in MAVProxy's .tlog format: each frame, in or out, preceded by its arrival
time as a big-endian 64-bit count of microseconds since the Unix epoch (what mavlogdump.py and
MAVExplorer read). Frames are buffered on the event loop and handed, when the buffer passes
BUFFER_BYTES or on `flush()` (the daemon flushes every second), to this file's own worker thread,
which writes them in order: the loop never waits for the disk. `close()` (at stop) waits for the
worker and writes the rest. When the file passes `max_bytes` it is rotated (by the worker):
NAME -> NAME.1 -> NAME.2 ..., keeping `keep` old files. A failed write is logged
(`tlog_write_failed`) and the frames of that chunk are lost; the daemon goes on."""

from __future__ import annotations

import concurrent.futures
import os
import struct
from pathlib import Path

import structlog

log = structlog.get_logger("gcsd.links.tlog")

BUFFER_BYTES = 64 * 1024
DEFAULT_MAX_BYTES = 64 * 1024 * 1024
DEFAULT_KEEP = 5
_STAMP = struct.Struct(">Q")


class TlogWriter:
    def __init__(self, path: str | os.PathLike, max_bytes: int = DEFAULT_MAX_BYTES, keep: int = DEFAULT_KEEP) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.max_bytes = max_bytes
        self.keep = keep
        self._buf = bytearray()
        self._file = open(self.path, "ab")  # noqa: SIM115  (open for the daemon's life; close() closes it)
        self._size = self._file.tell()
        self.frames = 0
        self._worker = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="gcsd-tlog")

    def record(self, raw: bytes, wall_s: float) -> None:
        self._buf += _STAMP.pack(int(wall_s * 1e6))
        self._buf += raw
        self.frames += 1
        if len(self._buf) >= BUFFER_BYTES:
            self.flush()

    def flush(self) -> None:
        """Hand what is buffered to the worker thread (returns at once)."""
        if not self._buf or self._file is None:
            return
        chunk, self._buf = bytes(self._buf), bytearray()
        self._worker.submit(self._write, chunk)

    def _write(self, chunk: bytes) -> None:
        """On the worker thread: one chunk, in order; rotation when the file is full."""
        try:
            self._file.write(chunk)
            self._file.flush()
            self._size += len(chunk)
            if self._size >= self.max_bytes:
                self._rotate()
        except (OSError, ValueError) as exc:  # ValueError: the file was closed under a failed rotation
            log.error("tlog_write_failed", path=str(self.path), error=str(exc), bytes=len(chunk))

    def _rotate(self) -> None:
        self._file.close()
        for n in range(self.keep - 1, 0, -1):
            older = self.path.with_name(f"{self.path.name}.{n}")
            if older.exists():
                older.replace(self.path.with_name(f"{self.path.name}.{n + 1}"))
        self.path.replace(self.path.with_name(f"{self.path.name}.1"))
        self._file = open(self.path, "ab")  # noqa: SIM115  (the next file of the rotation, as above)
        self._size = 0

    def close(self) -> None:
        """Everything recorded is written when this returns."""
        self.flush()
        self._worker.shutdown(wait=True)
        if self._file is not None:
            self._file.close()
            self._file = None
