"""A flight controller's MAVLink log backend, as ArduPilot's AP_Logger_MAVLink behaves
(REFERENCE.md 15), for capture tests. Pure: `poll(now)` returns the blocks to send.

- Streams only after a START (REMOTE_LOG_BLOCK_STATUS seqno 2147483646, status != 0); a START
  while streaming is ignored; STOP stops it; a new START begins a new log at seqno 0.
- Log data (`write(data)`) fills 200-byte blocks; only full blocks are sent. At most BLOCKCOUNT
  blocks are in flight (unacknowledged); when they are all taken, new data is dropped
  (`dropped_bytes`), never delayed, as ArduPilot does.
- ACK frees a block; NACK moves a sent block to the retry queue (sent before new blocks); every
  block sent more than RESEND_S ago and not acknowledged is sent again.
- No ACK/NACK for TIMEOUT_S while there was something to send: it stops; late ACKs do not
  restart it. An idle stream (nothing to send) never times out.
- `reboot()`: everything is lost; it streams again only after a new START.

`logged` is the byte stream of the current log as block contents by seqno: what the captured
file must equal.
"""

from __future__ import annotations

from collections import OrderedDict

START, STOP = 2147483646, 2147483645
BLOCK = 200
BLOCKCOUNT = 40
RESEND_S = 0.1
TIMEOUT_S = 10.0


class FakeLoggerFC:
    def __init__(self) -> None:
        self.streaming = False
        self.client: tuple[int, int] | None = None
        self.logs: list[dict[int, bytes]] = []  # every log started, blocks by seqno
        self.dropped_bytes = 0
        self.starts = 0
        self._reset(0.0)

    def _reset(self, now: float) -> None:
        self.next_seq = 0
        self.current = bytearray()
        self.pending: list[int] = []
        self.retry: list[int] = []
        self.sent: OrderedDict[int, float] = OrderedDict()  # seqno -> last sent
        self.blocks: dict[int, bytes] = {}
        self.last_response_s = now
        self.last_send_s = now

    @property
    def logged(self) -> bytes:
        blocks = self.logs[-1] if self.logs else {}
        return b"".join(blocks[i] for i in range(len(blocks)))

    def in_flight(self) -> int:
        return len(self.pending) + len(self.retry) + len(self.sent)

    def handle_status(self, seqno: int, status: int, sender: tuple[int, int], now: float) -> None:
        if seqno == STOP:
            self.streaming = False
            return
        if seqno == START:
            if status and not self.streaming:
                self._reset(now)
                self.streaming, self.client = True, sender
                self.starts += 1
                self.logs.append(self.blocks)
            return
        if not self.streaming:
            return
        if status:  # ACK
            if seqno in self.sent or seqno in self.retry:
                self.sent.pop(seqno, None)
                if seqno in self.retry:
                    self.retry.remove(seqno)
                self.last_response_s = now
        elif seqno in self.sent:  # NACK
            del self.sent[seqno]
            self.retry.append(seqno)
            self.last_response_s = now

    def write(self, data: bytes) -> None:
        if not self.streaming:
            return
        for i in range(len(data)):
            if not self.current and self.in_flight() >= BLOCKCOUNT:
                self.dropped_bytes += len(data) - i
                return
            self.current.append(data[i])
            if len(self.current) == BLOCK:
                self.blocks[self.next_seq] = bytes(self.current)
                self.pending.append(self.next_seq)
                self.next_seq += 1
                self.current = bytearray()

    def poll(self, now: float) -> list[tuple[int, bytes]]:
        if not self.streaming:
            return []
        if self.in_flight() and now - self.last_response_s > TIMEOUT_S:
            self.streaming = False
            return []
        out = []
        for queue in (self.retry, self.pending):
            while queue:
                seq = queue.pop(0)
                self.sent[seq] = now
                out.append(seq)
        for seq, last in list(self.sent.items()):
            if now - last >= RESEND_S and seq not in out:
                self.sent[seq] = now
                out.append(seq)
        if out:
            self.last_send_s = now
        return [(seq, self.blocks[seq]) for seq in out]

    def reboot(self) -> None:
        self.streaming = False
        self.client = None
