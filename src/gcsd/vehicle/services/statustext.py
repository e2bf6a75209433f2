"""STATUSTEXT queue with chunking, as GCS::send_textv / service_statustext.

Text up to 50 bytes is one message with id 0. Longer text (up to 250 bytes) is split into
50-byte chunks sharing an id from a 16-bit counter that skips 0, chunk_seq 0, 1, 2...; the last
chunk is shorter than 50 bytes (an empty chunk when the length is a multiple of 50). The queue
holds 30 entries (oldest dropped, counted), each pending on the channels it must still reach;
entries older than 5 s are dropped.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as M

CHUNK = 50
MAX_TEXT = 250
QUEUE_LEN = 30
MAX_AGE_S = 5.0


@dataclass
class _Entry:
    msg: object
    pending: set[int]
    created_s: float


def chunk_text(text: str, severity: int, text_id: int) -> list:
    """STATUSTEXT messages for one text; text_id is used only when more than one is needed."""
    data = text.encode("utf-8", "replace")[:MAX_TEXT]
    if len(data) <= CHUNK:
        return [M.MAVLink_statustext_message(severity, data, 0, 0)]
    chunks = [data[i:i + CHUNK] for i in range(0, len(data), CHUNK)]
    if len(data) % CHUNK == 0:
        chunks.append(b"")
    return [M.MAVLink_statustext_message(severity, c, text_id, seq) for seq, c in enumerate(chunks)]


class StatusTextQueue:
    def __init__(self) -> None:
        self._queue: deque[_Entry] = deque()
        self._next_id = 1
        self.dropped = 0

    def add(self, severity: int, text: str, channels: set[int], now: float) -> None:
        if not channels:
            return
        msgs = chunk_text(text, severity, self._next_id)
        if len(msgs) > 1:
            self._next_id = self._next_id % 0xFFFF + 1
        for msg in msgs:
            if len(self._queue) >= QUEUE_LEN:
                self._queue.popleft()
                self.dropped += 1
            self._queue.append(_Entry(msg, set(channels), now))

    def pending_for(self, channel: int) -> bool:
        return any(channel in e.pending for e in self._queue)

    def drain(self, channel: int, now: float, send) -> bool:
        """Send what is pending on a channel, oldest first; False if the link filled up."""
        while self._queue and now - self._queue[0].created_s > MAX_AGE_S:
            self._queue.popleft()
            self.dropped += 1
        for entry in list(self._queue):
            if channel not in entry.pending:
                continue
            if not send(entry.msg):
                return False
            entry.pending.discard(channel)
        while self._queue and not self._queue[0].pending:
            self._queue.popleft()
        return True
