"""BurstReadFile: the packets of one burst, and the pace they go at. Pure; `now` is passed in.

**Packets.** From the requested offset, chunks of the requested block size (239 when 0). The
packet that ends the burst carries burst_complete = 1: the BURST_PACKETS-th (2000, as ArduPilot
master), or a short chunk. A short chunk, or a read that comes exactly to the end, is followed by
NAK EOF carrying the end offset. Reply seq = request seq + 1 for the first packet, + 1 per
packet after (ArduPilot's numbering; QGroundControl checks it).

**Every burst_complete packet goes twice** (same seq, same bytes), the EOF NAK too. Losing it
costs the client a retry timeout (MAVSDK then fetches the whole rest of the file lock-step), so
on a 10 % loss link one copy in 100 is lost instead of one in 10. MAVSDK drops the copy by its
seq, MAVProxy as an offset it already has, QGroundControl as an old seq.

**Pace** (not in ArduPilot, which sends as fast as the link takes): a client's socket buffer
holds ~160 datagrams and a Python ground station reads some thousands a second, less on a
busy machine, so an unpaced burst on loopback loses its tail (measured: MAVProxy, 500-packet
bursts, 2 MB: 3 182 gap reads, 9.7 s). Each session keeps a rate: it starts at START_PPS (5 000
packets/s, 1.2 MB/s), grows by ADD_PPS (500) after every PROBE_PACKETS (100) packets sent
without a loss signal, up to MAX_PPS, and halves (down to MIN_PPS) on a loss signal: a read
for an offset the running burst has already passed, which is how a client asks for a gap. At
most one halving per HOLD_PACKETS (50) packets, since a client asks for a lost run of packets
in a batch. Measured on loopback (2 cores): a fast client reads 10 MB at 6-8 MB/s; MAVProxy
gets 2 MB in under 3 s with a few hundred gap reads (10 000/s fixed: 0 gaps but 2.4 MB/s for
everyone; 15 000/s fixed: 2 700 gaps). A packet is due at its send time; up to SLACK_S early is
allowed so that a send pass can take a few at once. The link's byte budget (configured
bandwidth) paces on top of this in the adapter.
"""

from __future__ import annotations

from dataclasses import dataclass

from gcsd.vehicle.ftp.protocol import DATA_MAX, FtpError, Nak, Payload

BURST_PACKETS = 2000
START_PPS = 5_000.0
MIN_PPS = 2_000.0
MAX_PPS = 50_000.0
ADD_PPS = 500.0
DECREASE = 0.5
PROBE_PACKETS = 100
HOLD_PACKETS = 50
SLACK_S = 0.002


@dataclass(slots=True)
class Pace:
    """A session's burst rate; it outlives bursts, so the next one starts where this one ended."""

    rate_pps: float = START_PPS
    clean: int = 0
    since_decrease: int = HOLD_PACKETS

    def sent(self) -> None:
        self.clean += 1
        self.since_decrease += 1
        if self.clean >= PROBE_PACKETS:
            self.rate_pps = min(MAX_PPS, self.rate_pps + ADD_PPS)
            self.clean = 0

    def loss(self) -> None:
        self.clean = 0
        if self.since_decrease >= HOLD_PACKETS:
            self.rate_pps = max(MIN_PPS, self.rate_pps * DECREASE)
            self.since_decrease = 0


@dataclass(slots=True)
class Burst:
    request: Payload
    raw: bytes  # the request as received, to recognise a repeat
    offset: int
    block: int
    next_s: float  # when the next packet is due
    sent: int = 0
    repeat: Payload | None = None  # a burst_complete packet, to send once more
    finished: bool = False  # ends once `repeat` is out

    @classmethod
    def start(cls, request: Payload, now: float) -> Burst:
        block = min(request.size, DATA_MAX) or DATA_MAX
        return cls(request, request.pack(), request.offset, block, now)

    def due(self, now: float) -> bool:
        return self.next_s <= now + SLACK_S

    def next_packet(self, handle, pace: Pace, now: float) -> Payload:
        """The next packet (the caller checks `due` first); `finished` says whether it was the last."""
        self.next_s = max(self.next_s, now - SLACK_S) + 1.0 / pace.rate_pps
        if self.repeat is not None:
            packet, self.repeat = self.repeat, None
            return packet
        step = 1 + self.sent
        try:
            data = handle.read(self.offset, self.block) if handle is not None else b""
            error = None
        except FtpError as exc:
            data, error = b"", exc
        if not data:
            code, errno_value = (error.code, error.errno_value) if error else (Nak.EOF, 0)
            self.repeat = self.request.nak(code, errno_value, offset=self.offset, burst_complete=1,
                                           seq_step=step)
            self.finished = True
            return self.repeat
        self.sent += 1
        pace.sent()
        short = len(data) < self.block
        last = short or self.sent >= BURST_PACKETS
        packet = self.request.ack(data, offset=self.offset, burst_complete=int(last), seq_step=step)
        self.offset += len(data)
        if last:
            self.repeat, self.finished = packet, not short
        return packet

    @property
    def done(self) -> bool:
        return self.finished and self.repeat is None
