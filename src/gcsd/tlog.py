"""Telemetry logs in MAVProxy's .tlog format: each frame, in or out, preceded by its arrival
time as a big-endian 64-bit count of microseconds since the Unix epoch (what mavlogdump.py and
MAVExplorer read). Frames are buffered and written when the buffer passes BUFFER_BYTES or on
`flush()` (the daemon flushes every second and at stop). When the file passes `max_bytes` it is
rotated: NAME -> NAME.1 -> NAME.2 ..., keeping `keep` old files."""

from __future__ import annotations

import os
import struct
from pathlib import Path

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
        self._file = open(self.path, "ab")
        self._size = self._file.tell()
        self.frames = 0

    def record(self, raw: bytes, wall_s: float) -> None:
        self._buf += _STAMP.pack(int(wall_s * 1e6))
        self._buf += raw
        self.frames += 1
        if len(self._buf) >= BUFFER_BYTES:
            self.flush()

    def flush(self) -> None:
        if not self._buf or self._file is None:
            return
        self._file.write(self._buf)
        self._file.flush()
        self._size += len(self._buf)
        self._buf.clear()
        if self._size >= self.max_bytes:
            self._rotate()

    def _rotate(self) -> None:
        self._file.close()
        for n in range(self.keep - 1, 0, -1):
            older = self.path.with_name(f"{self.path.name}.{n}")
            if older.exists():
                older.replace(self.path.with_name(f"{self.path.name}.{n + 1}"))
        self.path.replace(self.path.with_name(f"{self.path.name}.1"))
        self._file = open(self.path, "ab")
        self._size = 0

    def close(self) -> None:
        self.flush()
        if self._file is not None:
            self._file.close()
            self._file = None
