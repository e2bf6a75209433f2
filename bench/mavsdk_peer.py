"""MAVSDK (the `mavsdk` package's C++ core) as the peer the benchmarks compare gcsd with.

`node(url, autopilot)` is a Mavsdk instance on one connection, destroyed on exit;
`serve_until_sigterm(server)` prints "ready" (what the bench waits for), runs until SIGTERM and
destroys the server plugin; `client_run(port, body)` connects a ground station to the autopilot
on a port and prints body's figures as one `RESULT {json}` line, errors included.
"""

from __future__ import annotations

import json
import signal
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager


@contextmanager
def node(url: str, autopilot: bool) -> Iterator:
    from mavsdk.component_type import ComponentType
    from mavsdk.mavsdk import Configuration, Mavsdk

    kind = ComponentType.AUTOPILOT if autopilot else ComponentType.GROUND_STATION
    mavsdk = Mavsdk(Configuration.create_with_component_type(kind))
    try:
        mavsdk.add_any_connection(url)
        yield mavsdk
    finally:
        mavsdk.destroy()


def serve_until_sigterm(server, on_stop: Callable[[], None] | None = None) -> int:
    stop: list[int] = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    print("ready", flush=True)
    while not stop:
        time.sleep(0.1)
    if on_stop is not None:
        on_stop()
    server.destroy()
    return 0


def client_run(port: int, body: Callable[[object, dict], None], out: dict) -> int:
    """A ground station on udpout://127.0.0.1:port; body(system, out) fills `out`."""
    try:
        with node(f"udpout://127.0.0.1:{port}", autopilot=False) as mavsdk:
            system = mavsdk.first_autopilot(10.0)
            if system is None:
                out["error"] = "no autopilot within 10 s"
            else:
                body(system, out)
    except Exception as exc:  # reported in the table, not a crash of the whole bench
        out["error"] = repr(exc)
    print("RESULT " + json.dumps(out), flush=True)
    return 0
