"""The HTTP API over a built daemon, served on the daemon's loop (gcsd.api.http.wiring adds it).

`HttpService.attach(gcs)` builds the face over the daemon; compose.py adds its `tap` to the
daemon's taps (every accepted frame, before routing, on every channel, also those added at run
time). `open()` is what opening the `http` channel does
(gcsd.api.http.local): bind `http.address` (an OSError is the transport's to log and retry), log
`http_listening` with the bound address (port 0 picks one; it is the `http` channel's address
in `gcsd status` and `http_address` in /v1/status), and hand back the channel's closer, which
stops listening and closes every connection within SHUTDOWN_TIMEOUT_S.

A port another process holds (a second gcsd on the host: a swarm, a fleet instance, a parallel
test) costs only the API: the transport tries again with its backoff (logged once per distinct
error), `state()` says why it is not listening (`gcsd status`, systemd's READY status line), and
neither READY nor the MAVLink channels wait for it.

Connections are bounded, inside the daemon's descriptor budget (`attach` raises it by
MAX_CONNECTIONS + 1 for the API, gcsd.links.tcpserver): at most MAX_CONNECTIONS at once. One
beyond closes the oldest connection that has not yet sent a whole request head (an idle or a
slow one: counted in `refused["idle_replaced"]`), so a client that asks is served whatever sits
idle; when every connection is busy with a request, the new one is answered 503 and closed at
once (`refused["connections"]`). asyncio accepts up to ACCEPT_BACKLOG connections per wake-up
before any is closed: the budget counts those too. A connection
must deliver a whole request head within KEEPALIVE_S of being opened or of its last answer, and
an idle keep-alive connection is closed after KEEPALIVE_S (aiohttp's keep-alive timer runs from
the connection's start and cuts a connection still waiting for a head: slowloris included); a
body must arrive within routes.BODY_TIMEOUT_S (408). With `signing.require` and no token the API
is read-only (gcsd.api.http.guard), said once in the log when it starts listening.
"""

from __future__ import annotations

import asyncio
import functools

import structlog
from aiohttp import web

from gcsd.api.http.face import Face
from gcsd.api.http.guard import Guard
from gcsd.api.http.local import LocalChannel
from gcsd.api.http.routes import build_app
from gcsd.config import Config
from gcsd.config.http import read_token
from gcsd.links import tcpserver
from gcsd.payloads.logs.listing import list_logs

log = structlog.get_logger("gcsd.api.http")

SHUTDOWN_TIMEOUT_S = 1.0
MAX_CONNECTIONS = 64 + 8  # clients, and the status page's two WebSockets and its fetches
KEEPALIVE_S = 5.0
ACCEPT_BACKLOG = 128  # the listen backlog; asyncio also accepts up to this many per wake-up
HEAD_END = b"\r\n\r\n"
_REFUSED = (b"HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\nConnection: close\r\n"
            b"Content-Length: %d\r\n\r\n%s")


class HttpService:
    def __init__(self, config: Config, channel: LocalChannel, gcs) -> None:
        self.config = config
        self.address: tuple[str, int] | None = None  # bound, once listening
        self.listen_error: str | None = None  # why the last attempt to listen failed, until one succeeds
        self._runner: web.AppRunner | None = None
        self._closing: set[asyncio.Future] = set()
        self._gcs_status = gcs.status
        self._channels = gcs.channels  # the daemon's live list (channels come and go at run time)
        self._errors = gcs.errors
        self._now = gcs.clock.now
        self._server: asyncio.AbstractServer | None = None
        self._open: dict[_Counted, None] = {}  # the connections open now, oldest first
        self.read_only = config.signing.require and config.http.token_file is None
        self.guard = Guard(lambda: self.address, self.read_only, config.http.token_file is not None)
        self._said_read_only = False
        self.face = Face(channel, gcs.nodes, self.status, gcs.errors, gcs.clock.now, gcs.clock.wall,
                         functools.partial(list_logs, config))
        self.face.raw_channel = self.raw_channel  # /v1/ws/raw (gcsd.links.websocket)

    @classmethod
    def attach(cls, gcs) -> HttpService | None:
        """The API over a built daemon (None when `http.address` is null); taps every channel."""
        channel = next((ch for ch in gcs.channels if isinstance(ch, LocalChannel)), None)
        if channel is None:
            return None
        service = cls(gcs.config, channel, gcs)
        channel.opener = service.open
        service.share_access(gcs.channels)
        # the daemon's descriptor budget with the API's share (gcsd.links.tcpserver): raised if short
        limit, needed = tcpserver.ensure_descriptor_budget(
            tcpserver.descriptors_needed(gcs.config.channels, MAX_CONNECTIONS + ACCEPT_BACKLOG))
        if limit < needed:
            log.warning("descriptor_budget_short", limit=limit, needed=needed, http_connections=MAX_CONNECTIONS)
        return service

    def share_access(self, channels) -> None:
        """The API's token and read-only rule for the websocket channels' own listeners."""
        from gcsd.links.websocket import WEBSOCKET_TYPE, Access

        try:
            token = read_token(self.config.http.token_file) if self.config.http.token_file else None
        except (OSError, ValueError):
            token = "\x00unreadable"  # preflight refuses such a file; never an open listener
        for ch in channels:
            if ch.config.type == WEBSOCKET_TYPE:
                ch.access = Access(token, self.read_only, self.guard.count)

    def raw_channel(self):
        """The websocket channel /v1/ws/raw serves (the first configured), or None."""
        return next((ch for ch in self._channels if ch.config.type == "websocket" and not ch.retired), None)

    def status(self) -> dict:
        document = self._gcs_status()
        document["http_address"] = None if self.address is None else f"{self.address[0]}:{self.address[1]}"
        peers = {ch.name: [_peer_name(key) for key in ch.peers] for ch in self._channels}
        for entry in document["channels"]:  # who each channel serves, for the page
            entry["peer_addresses"] = peers.get(entry["name"], [])
        return document

    def state(self) -> dict:
        """The listener for `gcsd status`: the configured address, the bound one (None while not
        listening) and the last error while not listening."""
        host, port = self.config.http.address
        return {"address": f"{host}:{port}",
                "listening": None if self.address is None else f"{self.address[0]}:{self.address[1]}",
                "error": None if self.address is not None else self.listen_error,
                "read_only": self.read_only, "connections": len(self._open),
                "max_connections": MAX_CONNECTIONS, "refused": dict(sorted(self.guard.refused.items()))}

    def tap(self, channel, frame, now: float) -> None:
        """The daemon's tap (compose.py): every accepted frame, before routing, at the wall time
        of the channel's wake-up. The tree's own guard: a fault here is counted and never costs
        the frame its routing."""
        try:
            self.face.frame_seen(frame, channel.out.time.wall)
        except Exception:  # noqa: BLE001  (the tree's guard: counted, the frame is still routed)
            self._errors.failed("http:tap", self._now(), channel=channel.name, msg=frame.name)

    async def open(self) -> tuple:
        http = self.config.http
        if self._runner is None:
            token = read_token(http.token_file) if http.token_file else None
            self._runner = web.AppRunner(build_app(self.face, token, self.guard, self.config.metrics), access_log=None,
                                         handle_signals=False, shutdown_timeout=SHUTDOWN_TIMEOUT_S,
                                         keepalive_timeout=KEEPALIVE_S)
            await self._runner.setup()
        runner = self._runner
        host, port = http.address
        try:
            server = await asyncio.get_running_loop().create_server(
                functools.partial(self._connection, runner), host, port, reuse_address=True, backlog=ACCEPT_BACKLOG)
        except OSError as exc:
            self.listen_error = exc.strerror or str(exc)
            self._runner = None
            await runner.cleanup()
            raise
        self._server = server
        self.listen_error = None
        self.address = tuple(server.sockets[0].getsockname()[:2]) if server.sockets else (host, port)
        self.face.channel.local_address = self.address
        log.info("http_listening", address=f"{self.address[0]}:{self.address[1]}",
                 token=http.token_file is not None, max_connections=MAX_CONNECTIONS)
        if self.read_only and not self._said_read_only:
            self._said_read_only = True
            log.warning("http_read_only", reason="signing.require is true and http.token_file is not set: "
                        "POST, PUT and WebSocket sends are refused (403); set http.token_file to allow them")

        def close() -> None:
            self.address = None
            server.close()
            if self._runner is runner:
                self._runner = None
            self._closing.add(asyncio.ensure_future(runner.cleanup()))

        return close, asyncio.get_running_loop().create_future()

    def _connection(self, runner: web.AppRunner) -> asyncio.Protocol:
        """The protocol of an accepted connection: aiohttp's, counted; at the cap the oldest that
        has sent no request head yet makes room, or else a 503."""
        if len(self._open) >= MAX_CONNECTIONS:
            waiting = next((c for c in self._open if not c.head_seen and c.connected), None)
            if waiting is None or runner.server is None:
                self.guard.count("connections")
                return _Refused()
            self.guard.count("idle_replaced")
            self._open.pop(waiting)
            waiting.abort()
        if runner.server is None:
            return _Refused()
        conn = _Counted(runner.server(), self._open)
        self._open[conn] = None
        return conn


class _Counted(asyncio.Protocol):
    """aiohttp's protocol for one connection, in the table of open ones until it is gone; whether
    its first request head has arrived (an older one that has not is the first to make room)."""

    def __init__(self, inner, table: dict) -> None:
        self.inner, self._table = inner, table
        self.head_seen = False
        self._tail = b""
        self._transport = None

    @property
    def connected(self) -> bool:
        return self._transport is not None

    def abort(self) -> None:
        if self._transport is not None:
            self._transport.abort()

    def connection_made(self, transport) -> None:
        self._transport = transport
        self.inner.connection_made(transport)

    def data_received(self, data: bytes) -> None:
        if not self.head_seen:
            seen = self._tail + data
            self.head_seen = HEAD_END in seen
            self._tail = seen[-3:]
        self.inner.data_received(data)

    def eof_received(self):
        return self.inner.eof_received()

    def pause_writing(self) -> None:
        self.inner.pause_writing()

    def resume_writing(self) -> None:
        self.inner.resume_writing()

    def connection_lost(self, exc) -> None:
        self._table.pop(self, None)
        self._transport = None
        self.inner.connection_lost(exc)


class _Refused(asyncio.Protocol):
    """A connection beyond MAX_CONNECTIONS: one 503 and closed, its descriptor given back at once."""

    def connection_made(self, transport) -> None:
        body = b'{"error": "too many HTTP connections; try again"}'
        transport.write(_REFUSED % (len(body), body))
        transport.close()


def _peer_name(key: object) -> str:
    return f"{key[0]}:{key[1]}" if isinstance(key, tuple) and len(key) == 2 else str(key)
