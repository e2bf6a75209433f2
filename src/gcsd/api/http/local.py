"""The HTTP API as a MAVLink channel of the daemon (type `local`, named `http`).

Built by the composition root after the configured channels (gcsd.api.http.wiring), so
every vehicle has a Link on it and answers on it like on any other channel: the message tree
then holds our own vehicles' telemetry whether or not any ground station is connected, and the
replies to what was sent over HTTP. It is no MAVLink channel a ground station sets rates on:
its streams run at the fixed defaults (DEFAULT_STREAM_RATES_HZ), it has no SRn_ parameters and
takes none of the MAX_CHANNELS MAVLink slots (config_schema.mavlink_slot), so the parameter set
is ArduPilot's with or without the API, and READY counts only the MAVLink channels.

- Out (our vehicles' messages): `send_message` hands the pymavlink message to `sink(sysid,
  compid, seq, msg)` without encoding it; nothing else carries it into the tree, so each is
  counted once however many channels also carry it. It has one permanent peer (the API), no
  byte budget, and counts packets_out.
- Routed frames written to it (`write`) are dropped: the tree already took them when they were
  received (the daemon's frame tap), and nothing leaves the process through it.
- In (`inject`, POST /v1/mavlink and the WebSocket): the message is encoded under the client's
  header (sysid, compid; the sequence is this channel's own per source), parsed back into a
  Frame by the peer's parser (counted in packets_in) and given to `on_frame` as if it had
  arrived here: routed to the other channels, handled by our vehicles when addressed to them,
  learned as a route. The channel has `options: [sign_forwarded]`: where signing is active the
  daemon's signing gateway signs what it forwards (link id = this channel's index, a fresh
  timestamp), as for any trusted local tool (SPEC.md "Signing gateway").
- Opening it is opening the API (`open`, through `opener`, set by gcsd.api.http.service): the
  channel task of `transport.run_channel` binds `http.address`, then runs the send passes as for
  every channel. A port that cannot be bound is what a client channel that cannot connect is:
  logged (`channel_open_failed`, once per distinct error) and tried again with the transport's
  backoff; the daemon keeps flying without its HTTP face meanwhile, READY is not held for it, and
  `gcsd status` says why it is not listening (gcsd.api.http.service).
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable

from gcsd.config import ChannelConfig
from gcsd.config.schema import LOCAL_TYPE
from gcsd.links.channel import Channel
from gcsd.links.outbox import Outbox
from gcsd.wire.codec import Encoder, MAVLink_message

PEER_KEY = "http-api"


def local_channel_config(name: str = "http") -> ChannelConfig:
    return ChannelConfig(name=name, type=LOCAL_TYPE, options=frozenset({"sign_forwarded"}))


class LocalOutbox(Outbox):
    """The API's output: our vehicles' messages to the sink unencoded, routed frames dropped, no
    byte budget. Replies go out through `send_message` too (Outbox.reply)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.sink: Callable[[int, int, int, MAVLink_message], None] = lambda sysid, compid, seq, msg: None
        self._out_seq: dict[tuple[int, int], int] = {}

    def has_room(self, nbytes: int = 0) -> bool:
        return True

    def write(self, raw: bytes) -> bool:
        return True

    def send_message(self, msg: MAVLink_message, sysid: int, compid: int) -> bool:
        key = (sysid, compid)
        seq = self._out_seq.get(key, 0)
        self._out_seq[key] = (seq + 1) & 0xFF
        self.stats.packets_out += 1
        self.sink(sysid, compid, seq, msg)
        return True


class LocalChannel(Channel):
    outbox_class = LocalOutbox

    def __init__(self, index: int, config: ChannelConfig, clock: Callable[[], float], **parts) -> None:
        super().__init__(index, config, clock, **parts)
        self._injectors: dict[tuple[int, int], Encoder] = {}
        self.add_peer(PEER_KEY, lambda raw: True, announce=False)  # the API: there from the start
        self.opener: Callable[[], Awaitable[tuple]] | None = None  # the API's listener (HttpService.open)

    async def open(self) -> tuple[Callable[[], None], asyncio.Future]:
        """What `transport.run_channel` opens: the API's listening socket; raises OSError."""
        if self.opener is None:
            raise OSError("the HTTP API is not attached")
        return await self.opener()

    @property
    def sink(self) -> Callable[[int, int, int, MAVLink_message], None]:
        return self.out.sink

    @sink.setter
    def sink(self, sink: Callable[[int, int, int, MAVLink_message], None]) -> None:
        self.out.sink = sink

    def inject(self, sysid: int, compid: int, msg: MAVLink_message, now: float) -> None:
        """A message from an API client: into the daemon as if received on this channel."""
        encoder = self._injectors.get((sysid, compid))
        if encoder is None:
            if len(self._injectors) >= 1024:
                self._injectors.clear()  # bounded: sequences restart for sources seen long ago
            encoder = self._injectors[(sysid, compid)] = Encoder(sysid, compid)
        raw = encoder.encode(msg, False, None)
        self.tick(now, self.wall())  # as a transport does at a wake-up: the time the frame is seen
        for frame in self.peers[PEER_KEY].parser.feed(raw):
            self.on_frame(self, frame, now)
