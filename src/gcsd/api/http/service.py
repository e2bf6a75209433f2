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
"""

from __future__ import annotations

import asyncio
import functools

import structlog
from aiohttp import web

from gcsd.api.http.face import Face
from gcsd.api.http.local import LocalChannel
from gcsd.api.http.routes import build_app
from gcsd.config import Config
from gcsd.config.http import read_token
from gcsd.payloads.logs.listing import list_logs

log = structlog.get_logger("gcsd.api.http")

SHUTDOWN_TIMEOUT_S = 1.0


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
        self.face = Face(channel, gcs.nodes, self.status, gcs.errors, gcs.clock.now, gcs.clock.wall,
                         functools.partial(list_logs, config))

    @classmethod
    def attach(cls, gcs) -> HttpService | None:
        """The API over a built daemon (None when `http.address` is null); taps every channel."""
        channel = next((ch for ch in gcs.channels if isinstance(ch, LocalChannel)), None)
        if channel is None:
            return None
        service = cls(gcs.config, channel, gcs)
        channel.opener = service.open
        return service

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
                "error": None if self.address is not None else self.listen_error}

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
            self._runner = web.AppRunner(build_app(self.face, token), access_log=None, handle_signals=False,
                                         shutdown_timeout=SHUTDOWN_TIMEOUT_S)
            await self._runner.setup()
        runner = self._runner
        host, port = http.address
        try:
            await web.TCPSite(runner, host, port).start()
        except OSError as exc:
            self.listen_error = exc.strerror or str(exc)
            self._runner = None
            await runner.cleanup()
            raise
        self.listen_error = None
        self.address = tuple(runner.addresses[0][:2]) if runner.addresses else (host, port)
        self.face.channel.local_address = self.address
        log.info("http_listening", address=f"{self.address[0]}:{self.address[1]}",
                 token=http.token_file is not None)

        def close() -> None:
            self.address = None
            if self._runner is runner:
                self._runner = None
            self._closing.add(asyncio.ensure_future(runner.cleanup()))

        return close, asyncio.get_running_loop().create_future()


def _peer_name(key: object) -> str:
    return f"{key[0]}:{key[1]}" if isinstance(key, tuple) and len(key) == 2 else str(key)
