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
  transfer; an id that is not a log ends it (as ArduPilot). After the last range: IDLE. A request
  that overlaps or touches a queued range joins it (MAVProxy asks for the same gaps again after
  each 0.7 s without data: nothing is queued twice; issue 27).
- A log listed (LOG_REQUEST_LIST) is served up to the size its LOG_ENTRY gave, even if it grew
  since (a log being captured): the range ends there on a short (or empty) chunk, so the
  client's download ends at the size it was told.
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
        self._listed: dict[str, int] = {}  # log name -> the size its LOG_ENTRY gave

    @property
    def busy(self) -> bool:
        return self.state != "IDLE"

    def request_list(self, entries: list[LogEntry], start: int, end: int) -> None:
        n = len(entries)
        self._ranges.clear()
        self._listed = {e.name: e.size for e in entries}
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
        listed = self._listed.get(name)
        if listed is not None:
            count = max(0, min(count, listed - ofs))  # a growing log: what was listed (past it: an empty chunk)
        self._queue(ofs, count)
        self.state = "SENDING"

    def _queue(self, ofs: int, count: int) -> None:
        """Queue `count` bytes from `ofs`, joined to a queued range it overlaps or touches (an
        empty range, the empty chunk at a log's end, stays on its own)."""
        end = ofs + count
        if count:
            for r in self._ranges:
                r_end = r[0] + r[1]
                if r[1] and ofs <= r_end and end >= r[0]:
                    start = min(r[0], ofs)
                    r[0], r[1] = start, max(r_end, end) - start
                    return
        if [ofs, count] not in self._ranges and len(self._ranges) < MAX_RANGES:
            self._ranges.append([ofs, count])

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
        # a range up to a listed log's end ends on a short (maybe empty) chunk, as the file's end would
        if nbytes < DATA_BYTES or (rng[1] <= 0 and rng[0] != self._listed.get(self._name)):
            self._ranges.popleft()
            if not self._ranges:
                self.state = "IDLE"
