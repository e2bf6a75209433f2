"""A small blocking HTTP client for the API tests (urllib), and WebSocket sessions (aiohttp).

`call(url, method, body)` returns (status, headers, parsed JSON or text, raw text); it never
raises for an HTTP error status. A POST or PUT says `Content-Type: application/json` unless
`headers` says otherwise (what a JSON client sends; urllib's own default is a form). `ws_frames(url, count)` reads text frames from a WebSocket.
"""

from __future__ import annotations

import asyncio
import json
import time
import urllib.error
import urllib.request

import aiohttp


def call(url: str, method: str = "GET", body: object = None, headers: dict | None = None,
         raw: bytes | None = None, timeout: float = 5.0):
    data = raw if raw is not None else (None if body is None else json.dumps(body).encode())
    headers = dict(headers or {})
    if data is not None or method in ("POST", "PUT"):  # what a JSON client says (urllib's default is a form)
        headers.setdefault("Content-Type", "application/json")
    request = urllib.request.Request(url, data=data, method=method, headers=headers)
    try:
        with urllib.request.urlopen(request, timeout=timeout) as response:
            status, hdrs, text = response.status, response.headers, response.read().decode("utf-8", "replace")
    except urllib.error.HTTPError as exc:
        status, hdrs, text = exc.code, exc.headers, exc.read().decode("utf-8", "replace")
    try:
        value = json.loads(text) if text else None
    except ValueError:
        value = text
    return status, hdrs, value, text


def get(url: str, **kw):
    return call(url, **kw)


def poll(fn, timeout: float = 5.0, interval: float = 0.05):
    """fn() until it returns something truthy, or None after `timeout`."""
    deadline = time.monotonic() + timeout
    while True:
        value = fn()
        if value:
            return value
        if time.monotonic() > deadline:
            return None
        time.sleep(interval)


async def _ws_frames(url: str, count: int, send: list | None, timeout: float, headers: dict | None):
    frames = []
    async with aiohttp.ClientSession() as session, session.ws_connect(url, headers=headers) as ws:
        for item in send or []:
            await ws.send_str(item if isinstance(item, str) else json.dumps(item))
        deadline = asyncio.get_running_loop().time() + timeout
        while len(frames) < count:
            left = deadline - asyncio.get_running_loop().time()
            if left <= 0:
                break
            try:
                msg = await ws.receive(timeout=left)
            except TimeoutError:
                break
            if msg.type != aiohttp.WSMsgType.TEXT:
                break
            frames.append(json.loads(msg.data))
    return frames


def ws_frames(url: str, count: int, send: list | None = None, timeout: float = 5.0, headers: dict | None = None):
    return asyncio.run(_ws_frames(url, count, send, timeout, headers))


async def _ws_status(url: str, headers: dict | None) -> int:
    async with aiohttp.ClientSession() as session:
        try:
            async with session.ws_connect(url, headers=headers):
                return 101
        except aiohttp.WSServerHandshakeError as exc:
            return exc.status


def ws_handshake_status(url: str, headers: dict | None = None) -> int:
    return asyncio.run(_ws_status(url, headers))
