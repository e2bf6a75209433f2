"""Load generators for bench/http.py, run as their own processes (their CPU is not gcsd's).

    python -m bench.http_load get URL CLIENTS SECONDS [START]   # CLIENTS keep-alive connections, GET in a loop
    python -m bench.http_load ws URL CLIENTS SECONDS [START]    # CLIENTS WebSockets, every frame read

START (seconds since the epoch) is when to begin, so that several processes load together.

Prints one JSON object: requests (or frames) done, errors, and for `get` the latency percentiles.
"""

from __future__ import annotations

import asyncio
import json
import sys
import time
from urllib.parse import urlsplit

import aiohttp


async def _get(url: str, clients: int, seconds: float) -> dict:
    """Keep-alive connections on raw asyncio streams (a request is a few microseconds of client CPU,
    so that the server, not the client, is what is measured); each response read whole."""
    parts = urlsplit(url)
    request = (f"GET {parts.path}{'?' + parts.query if parts.query else ''} HTTP/1.1\r\n"
               f"Host: {parts.netloc}\r\nAccept: */*\r\n\r\n").encode()
    latencies: list[float] = []
    errors = 0
    stop_at = time.monotonic() + seconds

    async def one() -> None:
        nonlocal errors
        reader, writer = await asyncio.open_connection(parts.hostname, parts.port)
        try:
            while time.monotonic() < stop_at:
                t0 = time.perf_counter()
                writer.write(request)
                head = await reader.readuntil(b"\r\n\r\n")
                length = 0
                for line in head.split(b"\r\n"):
                    if line[:15].lower() == b"content-length:":
                        length = int(line[15:])
                await reader.readexactly(length)
                if not head.startswith(b"HTTP/1.1 200"):
                    errors += 1
                latencies.append(time.perf_counter() - t0)
        except (OSError, asyncio.IncompleteReadError):
            errors += 1
        finally:
            writer.close()

    t0 = time.monotonic()
    await asyncio.gather(*(one() for _ in range(clients)))
    elapsed = time.monotonic() - t0
    latencies.sort()
    pct = (lambda q: latencies[min(len(latencies) - 1, int(q * len(latencies)))] * 1000 if latencies else None)
    return {"requests": len(latencies), "errors": errors, "elapsed_s": elapsed,
            "p50_ms": pct(0.5), "p99_ms": pct(0.99)}


async def _ws(url: str, clients: int, seconds: float) -> dict:
    frames = [0] * clients
    errors = 0

    async def one(i: int, session: aiohttp.ClientSession) -> None:
        nonlocal errors
        try:
            async with session.ws_connect(url) as ws:
                stop_at = time.monotonic() + seconds
                while (left := stop_at - time.monotonic()) > 0:
                    try:
                        msg = await ws.receive(timeout=left)
                    except TimeoutError:
                        break
                    if msg.type != aiohttp.WSMsgType.TEXT:
                        errors += 1
                        break
                    frames[i] += 1
        except aiohttp.ClientError:
            errors += 1

    async with aiohttp.ClientSession() as session:
        await asyncio.gather(*(one(i, session) for i in range(clients)))
    return {"frames": sum(frames), "per_client_min": min(frames), "errors": errors}


def main(argv: list[str]) -> int:
    kind, url, clients, seconds = argv[0], argv[1], int(argv[2]), float(argv[3])
    start_at = float(argv[4]) if len(argv) > 4 else time.time()  # wall clock: all processes start together
    time.sleep(max(0.0, start_at - time.time()))
    result = asyncio.run((_get if kind == "get" else _ws)(url, clients, seconds))
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
