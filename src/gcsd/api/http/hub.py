"""The WebSocket fan-out of `/v1/ws/mavlink`: every message the tree takes, to each client whose
filter matches its name.

A client's filter is a regular expression searched in the message name, unanchored, as
mavlink2rest's `regex::is_match` (`RC_.*` takes RC_CHANNELS and RC_CHANNELS_RAW; the default is
`.*`). `sysid` and `compid` (mavlink2rest #119, mavp2p #184), when given, keep only the messages
of that system and component. A frame is `{"header": {"system_id", "component_id", "sequence"}, "message": {...}}`,
encoded once per message however many clients take it. Each client has a bounded queue
(QUEUE_FRAMES); a client that does not keep up loses the newest frames, counted in `dropped` and
in the `http` channel's drops (`gcsd status`), and never slows the daemon or the other clients.
Pure: no sockets; the server drains the queues.
"""

from __future__ import annotations

import asyncio
import json
import re
from collections.abc import Callable

from gcsd.api.http.mavjson import message_json
from gcsd.wire.codec import Frame

QUEUE_FRAMES = 512


class Subscriber:
    __slots__ = ("compid", "matches", "pattern", "queue", "sysid")

    def __init__(self, pattern: re.Pattern, sysid: int | None = None, compid: int | None = None) -> None:
        self.pattern = pattern
        self.sysid, self.compid = sysid, compid
        self.queue: asyncio.Queue[str] = asyncio.Queue(QUEUE_FRAMES)
        self.matches: dict[str, bool] = {}

    def wants(self, name: str) -> bool:
        hit = self.matches.get(name)
        if hit is None:
            hit = self.matches[name] = self.pattern.search(name) is not None
        return hit


class Hub:
    def __init__(self, stats=None) -> None:
        self.subscribers: list[Subscriber] = []
        self.dropped = 0
        self.frames_sent = 0
        self._stats = stats  # ChannelStats of the http channel: its `drops` count ours too

    def subscribe(self, filter_text: str, sysid: int | None = None, compid: int | None = None) -> Subscriber:
        """Raises re.error for a filter that is not a regular expression."""
        sub = Subscriber(re.compile(filter_text), sysid, compid)
        self.subscribers.append(sub)
        return sub

    def unsubscribe(self, sub: Subscriber) -> None:
        if sub in self.subscribers:
            self.subscribers.remove(sub)

    def publish(self, sysid: int, compid: int, seq: int, name: str, msg,
                encode: Callable[[dict], str] = json.dumps) -> None:
        """`msg`: a pymavlink message or a Frame, decoded only if a subscriber takes `name`."""
        text = None
        for sub in self.subscribers:
            if not sub.wants(name) or (sub.sysid is not None and sub.sysid != sysid) \
                    or (sub.compid is not None and sub.compid != compid):
                continue
            if text is None:
                text = encode({"header": {"system_id": sysid, "component_id": compid, "sequence": seq},
                               "message": message_json(msg.msg if isinstance(msg, Frame) else msg)})
            try:
                sub.queue.put_nowait(text)
                self.frames_sent += 1
            except asyncio.QueueFull:
                self.dropped += 1
                if self._stats is not None:
                    self._stats.drops += 1
