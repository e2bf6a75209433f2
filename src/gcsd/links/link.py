"""A Link: one local component's view of one channel: its send scheduler and stream rates.

Stream rates start from the channel's configuration (the SRn_ values). REQUEST_DATA_STREAM
changes a stream's rate on this link and re-buckets its messages; SET_MESSAGE_INTERVAL changes
one message; interval 0 restores the default (the message's stream rate, 1000 ms for HEARTBEAT).
RADIO_STATUS txbuf drives the slowdown as ArduPilot's handle_radio_status does.

On a `high_latency` channel (REFERENCE.md section 11) the link sends HIGH_LATENCY2 every 5 s in
place of the HEARTBEAT and no SRn_ streams; elsewhere HIGH_LATENCY2 is sent only when asked.
"""

from __future__ import annotations

from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.links.scheduler import SendScheduler, ServiceShare
from gcsd.wire.streams import STREAM_MESSAGES, STREAM_OF_MESSAGE, rate_to_interval_ms

HEARTBEAT_MS = 1000
HIGH_LATENCY2_MS = 5000
MAX_SLOWDOWN_MS = 2000


class Link:
    def __init__(self, channel, now: float, producible: Callable[[int], bool], wake: Callable[[], None]) -> None:
        self.channel = channel
        self.high_latency = "high_latency" in channel.config.options
        self.scheduler = SendScheduler(now, special_ids=(M.MAVLINK_MSG_ID_HEARTBEAT, M.MAVLINK_MSG_ID_HIGH_LATENCY2))
        self._producible = producible
        self._wake = wake
        self.stream_rates: dict[str, float] = dict(channel.config.streams)
        self._slow_reasons: set[str] = set()
        budget = channel.out.budget
        # the services' guaranteed part of the channel's byte budget (None: no budget, no need)
        self.share = None if budget is None else ServiceShare(budget.rate_bps, budget.capacity, now)
        if self.high_latency:
            self.scheduler.set_interval(M.MAVLINK_MSG_ID_HIGH_LATENCY2, HIGH_LATENCY2_MS, now)
        else:
            self.scheduler.set_interval(M.MAVLINK_MSG_ID_HEARTBEAT, HEARTBEAT_MS, now)
        for stream, rate in self.stream_rates.items():
            self.set_stream_rate(stream, rate, now)

    def set_stream_rate(self, stream: str, rate_hz: float, now: float) -> None:
        self.stream_rates[stream] = rate_hz
        if self.high_latency:
            return  # no streams on a high-latency link
        interval = rate_to_interval_ms(rate_hz)
        for msgid in STREAM_MESSAGES[stream]:
            if self._producible(msgid):
                self.scheduler.set_interval(msgid, interval, now)

    def default_interval_ms(self, msgid: int) -> int:
        if msgid == M.MAVLINK_MSG_ID_HEARTBEAT:
            return 0 if self.high_latency else HEARTBEAT_MS
        if msgid == M.MAVLINK_MSG_ID_HIGH_LATENCY2:
            return HIGH_LATENCY2_MS if self.high_latency else 0
        stream = STREAM_OF_MESSAGE.get(msgid)
        return rate_to_interval_ms(self.stream_rates[stream]) if stream else 0

    def set_interval(self, msgid: int, interval_ms: int, now: float) -> None:
        self.scheduler.set_interval(msgid, interval_ms, now)
        self._wake()

    def reset_interval(self, msgid: int, now: float) -> None:
        self.set_interval(msgid, self.default_interval_ms(msgid), now)

    def interval_ms(self, msgid: int) -> int | None:
        return self.scheduler.interval_ms(msgid)

    def push(self, msgid: int) -> None:
        self.scheduler.push(msgid)
        self._wake()

    def set_slow(self, reason: str, active: bool) -> None:
        """Streams go x4 slower while any reason holds (a parameter list, a mission upload, FTP)."""
        if active:
            self._slow_reasons.add(reason)
        else:
            self._slow_reasons.discard(reason)
        self.scheduler.slow_factor = 4 if self._slow_reasons else 1

    def radio_txbuf(self, txbuf_pct: int, now: float) -> None:
        s = self.scheduler
        if txbuf_pct < 20:
            if s.slowdown_ms < MAX_SLOWDOWN_MS:
                s.slowdown_ms += 60
        elif txbuf_pct < 50:
            if s.slowdown_ms < MAX_SLOWDOWN_MS:
                s.slowdown_ms += 20
        elif txbuf_pct > 95:
            if s.slowdown_ms > 200:
                s.slowdown_ms -= 40
        elif txbuf_pct > 90:
            s.slowdown_ms = max(0, s.slowdown_ms - 20)
