"""The status page at `/`, its favicon, and `/v1/ws/status`, the WebSocket that feeds it.

The page (page/index.html, one file with its script and style; page/favicon.svg) loads nothing
from the internet. It opens `/v1/ws/status` (the `gcsd status` document every STATUS_PERIOD_S)
for the tables and `/v1/ws/mavlink` for the message rates and the vehicles' positions, and
reconnects every 2 s when a socket closes. At most MAX_STATUS_SOCKETS status sockets are open at
once (503 beyond); nothing is read from them.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable
from importlib import resources

from aiohttp import web

STATUS_PERIOD_S = 1.0
MAX_STATUS_SOCKETS = 64
OPEN = web.AppKey("status_sockets_open", list)


def install(app: web.Application, status: Callable[[], dict]) -> None:
    app[OPEN] = [0]

    async def status_ws(request: web.Request) -> web.StreamResponse:
        open_now = request.app[OPEN]
        if open_now[0] >= MAX_STATUS_SOCKETS:
            return web.json_response({"error": f"{MAX_STATUS_SOCKETS} status WebSockets already"}, status=503)
        open_now[0] += 1
        try:
            return await _serve(request, status)
        finally:
            open_now[0] -= 1

    app.router.add_get("/v1/ws/status", status_ws)
    app.router.add_get("/", page)
    app.router.add_get("/favicon.ico", favicon)


async def _serve(request: web.Request, status: Callable[[], dict]) -> web.StreamResponse:
    ws = web.WebSocketResponse(heartbeat=30.0)
    await ws.prepare(request)

    async def push() -> None:
        try:
            while not ws.closed:
                await ws.send_str(json.dumps(status(), default=str))
                await asyncio.sleep(STATUS_PERIOD_S)
        except ConnectionError:
            pass

    sender = asyncio.create_task(push())
    try:
        async for _frame in ws:
            pass  # nothing is taken on this socket
    finally:
        sender.cancel()
    return ws


def _asset(name: str) -> bytes:
    return resources.files("gcsd.api.http").joinpath("page", name).read_bytes()


async def page(request: web.Request) -> web.Response:
    return web.Response(body=_asset("index.html"), content_type="text/html", charset="utf-8")


async def favicon(request: web.Request) -> web.Response:
    return web.Response(body=_asset("favicon.svg"), content_type="image/svg+xml")
