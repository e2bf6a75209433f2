"""The `websocket` channel: binary MAVLink 2 over WebSocket, for browser tools that parse MAVLink
themselves (ArduPilot WebTools' TelemetryDashboard; SPEC.md "Web tools and monitoring").

A channel like the others (SRn_ streams, routing, filters, caps, signing, counters, a slot in
`gcsd status`): each WebSocket client is a peer, served from its first connection on, so the
streams flow unasked (WebTools never sends). Each binary frame is fed to the peer's parser as a
stream: a client may split a packet across frames or send several in one. A text frame is
refused with close code 1003 (unsupported data). What a client sends is routed and handled as
from any ground station; with `signing.require` and no `http.token_file` (the API read-only) it is
dropped, counted in the HTTP API's refusals (`read_only`).

It is served on the HTTP port at `/v1/ws/raw` (gcsd.api.http.routes: the API's token and guard
rules) and, with `address`, on a listener of its own (any path; `?token=` or a bearer header when
`http.token_file` is set), e.g. 127.0.0.1:56781, what WebTools tries on load. Each client's output
waits in a queue of its own; one that does not read is closed when its queue passes
MAX_QUEUE_BYTES, and nothing else waits for it.
"""

from __future__ import annotations

import asyncio
import hmac
import itertools
from collections import deque

import structlog
from aiohttp import WSCloseCode, WSMsgType, web

log = structlog.get_logger("gcsd.links.websocket")

WEBSOCKET_TYPE = "websocket"
MAX_QUEUE_BYTES = 1 << 20
MAX_FRAME_BYTES = 1 << 16  # a client's frame: many packets, never megabytes
HEARTBEAT_S = 30.0
_ids = itertools.count(1)


class Access:
    """The HTTP API's rules for the channel's own listener (gcsd.api.http.service sets
    `channel.access`): the token, read-only, and where a refusal is counted."""

    def __init__(self, token: str | None = None, read_only: bool = False, count=lambda reason: None) -> None:
        self.token, self.read_only, self.count = token, read_only, count


class _Client:
    """One WebSocket client's output: frames queued by the channel's send pass, sent by `drain`."""

    def __init__(self, ws: web.WebSocketResponse, transport) -> None:
        self.ws, self.transport = ws, transport
        self.queue: deque[bytes] = deque()
        self.queued = 0
        self.ready = asyncio.Event()
        self.dropped = False

    def write(self, data: bytes) -> bool:
        if self.dropped:
            return False
        if self.queued + len(data) > MAX_QUEUE_BYTES:  # it does not read: closed, nobody waits
            self.close()
            return False
        self.queue.append(data)
        self.queued += len(data)
        self.ready.set()
        return True

    def close(self) -> None:
        self.dropped = True
        if self.transport is not None:
            self.transport.abort()

    async def drain(self) -> None:
        try:
            while not self.ws.closed:
                await self.ready.wait()
                self.ready.clear()
                while self.queue:
                    data = self.queue.popleft()
                    self.queued -= len(data)
                    await self.ws.send_bytes(data)
        except (ConnectionError, RuntimeError):
            pass  # the client went away: the receive loop ends too


def token_ok(request: web.Request, token: str | None) -> bool:
    if token is None:
        return True
    given = request.query.get("token", "")
    header = request.headers.get("Authorization", "")
    if header.startswith("Bearer "):
        given = header[7:].strip()
    return hmac.compare_digest(given.encode(), token.encode())


async def serve(channel, request: web.Request, access: Access) -> web.WebSocketResponse:
    """One client of the channel, from the upgrade to the close."""
    ws = web.WebSocketResponse(heartbeat=HEARTBEAT_S, max_msg_size=MAX_FRAME_BYTES)
    await ws.prepare(request)
    client = _Client(ws, request.transport)
    peername = request.transport.get_extra_info("peername") if request.transport else None
    key = tuple(peername[:2]) if peername else f"ws-{next(_ids)}"
    peer = channel.connect_peer(key, client.write, client.close)
    log.info("peer_connected", channel=channel.name, peer=str(key))
    drain = asyncio.create_task(client.drain())
    try:
        async for msg in ws:
            if msg.type == WSMsgType.BINARY:
                if access.read_only:
                    access.count("read_only")
                    continue
                now = channel.clock()
                channel.tick(now, channel.wall())
                channel.receive(peer, msg.data, now)
            elif msg.type == WSMsgType.TEXT:
                await ws.close(code=WSCloseCode.UNSUPPORTED_DATA, message=b"binary MAVLink 2 frames only")
                break
    finally:
        drain.cancel()
        channel.remove_peer(key)
        log.info("peer_left", channel=channel.name, peer=str(key))
    return ws


async def open_channel(channel):
    """The transport's open: the listener of its own when `address` is set; (closer, closed)."""
    access = getattr(channel, "access", None) or Access()
    loop = asyncio.get_running_loop()
    closed = loop.create_future()
    runner = None
    if channel.config.address is not None:
        async def handler(request: web.Request) -> web.StreamResponse:
            if not token_ok(request, access.token):
                access.count("token")
                return web.json_response({"error": "a bearer token is required"}, status=401,
                                         headers={"WWW-Authenticate": 'Bearer realm="gcsd"'})
            return await serve(channel, request, access)

        app = web.Application()
        app.router.add_get("/{tail:.*}", handler)
        runner = web.AppRunner(app, access_log=None, handle_signals=False, shutdown_timeout=1.0)
        await runner.setup()
        host, port = channel.config.address
        site = web.TCPSite(runner, host, port, reuse_address=True)
        try:
            await site.start()
        except OSError:
            await runner.cleanup()
            raise
        channel.local_address = tuple(runner.addresses[0][:2])

    def close() -> None:
        channel.drop_all_peers()
        if runner is not None:
            loop.create_task(runner.cleanup())
        if not closed.done():
            closed.set_result(None)

    return close, closed
