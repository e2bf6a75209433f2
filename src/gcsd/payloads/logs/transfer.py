"""The MAVLink log protocol, server side (ArduPilot's AP_Logger_MAVLinkLogTransfer, REFERENCE.md 15).

Pure: one `LogTransfer` per requester (a ground station on one link); it takes requests with
the current list of logs and hands out what to send next. The service sends, paced by the
link's budget, and reads the files.

States: IDLE, LISTING, SENDING.
- LOG_REQUEST_LIST(start, end) -> LISTING: one `LogEntry` message per log from max(start, 1) to
  min(end, N) (ids 1-based, `num_logs` = `last_log_num` = N); with no logs, one entry with id 0
  and num_logs 0. Back to IDLE after the last entry.
- LOG_REQUEST_DATA(id, ofs, count) -> SENDING: `Chunk`s of up to DATA_BYTES (90) from `ofs`,
  in order. The service reads each and reports the bytes it got (`sent(n)`): a chunk shorter
  than 90 (the end of the file: 0 bytes at or past it) or the requested count reached ends that
  range. Further requests for the same log while sending are queued (up to MAX_RANGES; MAVProxy
  asks for up to 20 gaps at once; ArduPilot drops them), a request for another log replaces the
  transfer; an id that is not a log ends it (as ArduPilot). After the last range: IDLE.
- LOG_REQUEST_END -> IDLE. LOG_ERASE is the service's (the files), and ends the transfer.
No timeouts: a transfer ends by itself at the end of what was asked; a requester that went
away costs at most the rest of that file, paced by the link.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from gcsd.payloads.logs.store import LogEntry

DATA_BYTES = 90  # LOG_DATA.data
MAX_RANGES = 32
COUNT_MAX = 0xFFFFFFFF


@dataclass(frozen=True, slots=True)
class EntryMsg:
    """A LOG_ENTRY to send."""

    id: int
    num_logs: int
    last_log_num: int
    time_utc: int
    size: int


@dataclass(frozen=True, slots=True)
class Chunk:
    """A LOG_DATA to send: read up to `count` bytes of `name` at `ofs`."""

    id: int
    name: str
    ofs: int
    count: int


class LogTransfer:
    def __init__(self) -> None:
        self.state = "IDLE"
        self._listing: deque[EntryMsg] = deque()
        self._id = 0
        self._name = ""
        self._ranges: deque[list[int]] = deque()  # [ofs, remaining]

    @property
    def busy(self) -> bool:
        return self.state != "IDLE"

    def request_list(self, entries: list[LogEntry], start: int, end: int) -> None:
        n = len(entries)
        self._ranges.clear()
        if n == 0:
            self._listing = deque([EntryMsg(0, 0, 0, 0, 0)])
        else:
            first, last = max(start, 1), min(end, n)
            self._listing = deque(EntryMsg(e.id, n, n, e.time_utc, e.size) for e in entries[first - 1:last])
        self.state = "LISTING" if self._listing else "IDLE"

    def request_data(self, entries: list[LogEntry], log_id: int, ofs: int, count: int) -> None:
        if not 1 <= log_id <= len(entries):
            self.end()
            return
        name = entries[log_id - 1].name
        if self.state != "SENDING" or name != self._name or log_id != self._id:
            self._ranges.clear()
        self._listing.clear()
        self._id, self._name = log_id, name
        if [ofs, count] not in self._ranges and len(self._ranges) < MAX_RANGES:
            self._ranges.append([ofs, count])
        self.state = "SENDING"

    def end(self) -> None:
        self.state = "IDLE"
        self._listing.clear()
        self._ranges.clear()

    def next(self) -> EntryMsg | Chunk | None:
        """What to send next (without taking it: `taken()` / `sent(n)` do)."""
        if self.state == "LISTING":
            return self._listing[0]
        if self.state == "SENDING":
            ofs, remaining = self._ranges[0]
            return Chunk(self._id, self._name, ofs, min(DATA_BYTES, remaining))
        return None

    def taken(self) -> None:
        """The LOG_ENTRY from `next()` went out."""
        self._listing.popleft()
        if not self._listing:
            self.state = "IDLE"

    def sent(self, nbytes: int) -> None:
        """The chunk from `next()` went out carrying `nbytes`."""
        rng = self._ranges[0]
        rng[0] += nbytes
        rng[1] -= nbytes
        if nbytes < DATA_BYTES or rng[1] <= 0:
            self._ranges.popleft()
            if not self._ranges:
                self.state = "IDLE"
