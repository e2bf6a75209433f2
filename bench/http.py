"""The HTTP API under load, with a ground station's HEARTBEAT watched meanwhile.

One gcsd (the default simulated copter, one `udp-server` channel `gcs`, the API on a free
loopback port) and a pymavlink ground station on `gcs` sending its own HEARTBEAT at 1 Hz and
recording when each of the vehicle's arrives. Three windows of SECONDS each:

1. idle: the API unused (gcsd's CPU and the heartbeat intervals as a reference);
2. `get`: 10 keep-alive clients GET `/v1/mavlink/vehicles/1/components/1/messages/ATTITUDE` in a
   loop (bench/http_load.py, two processes of 5 so that the clients are not the limit): requests
   per second answered 200, latency p50/p99, gcsd's CPU;
3. `ws`: 20 WebSocket clients on `/v1/ws/mavlink` with no filter, at the default stream rates:
   frames delivered, gcsd's CPU (SPEC: at most 25 % of a core).

gcsd's CPU is utime + stime from /proc over the window. For each window the ground station's
HEARTBEAT intervals are reported (count, mean, largest): "undisturbed" means the same 1 Hz
with no gap beyond the idle window's.

    python -m bench http [--quick]
"""

from __future__ import annotations

import itertools
import json
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

from pymavlink import mavutil

from bench.measure import log
from bench.routers import cpu_seconds, free_udp_port, gcsd_config, start_gcsd

ENTRY = "/v1/mavlink/vehicles/1/components/1/messages/ATTITUDE"


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class HeartbeatWatch:
    """A ground station on the gcs channel: HEARTBEAT out at 1 Hz, the vehicle's recorded."""

    def __init__(self, port: int) -> None:
        self.conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255, source_component=190)
        self.arrivals: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        next_hb = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_hb:
                self.conn.mav.heartbeat_send(6, 8, 0, 0, 0)
                next_hb = now + 1.0
            msg = self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.1)
            if msg is not None and msg.get_srcSystem() == 1 and msg.get_srcComponent() == 1:
                self.arrivals.append(time.monotonic())

    def window(self, t0: float, t1: float) -> dict:
        times = [t for t in self.arrivals if t0 <= t <= t1]
        gaps = [b - a for a, b in itertools.pairwise(times)]
        return {"heartbeats": len(times), "mean_interval_s": sum(gaps) / len(gaps) if gaps else None,
                "max_interval_s": max(gaps) if gaps else None}

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.conn.close()


def _wait_ready(url: str, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            with urllib.request.urlopen(url + ENTRY, timeout=1) as response:
                if response.status == 200:
                    return
        except OSError:
            pass
        time.sleep(0.2)
    raise RuntimeError(f"the API did not answer {ENTRY} within {timeout_s:g} s")


START_DELAY_S = 2.0  # the load processes start (import aiohttp) before the measured window opens


def _load(kind: str, url: str, clients: int, seconds: float, processes: int, env) -> tuple[float, list]:
    per = clients // processes
    start_at = time.time() + START_DELAY_S
    argv = [sys.executable, "-m", "bench.http_load", kind, url, str(per), str(seconds), repr(start_at)]
    root = Path(__file__).resolve().parent.parent
    return start_at, [subprocess.Popen(argv, stdout=subprocess.PIPE, cwd=root, env=env) for _ in range(processes)]


def _results(procs: list[subprocess.Popen]) -> list[dict]:
    out = []
    for p in procs:
        stdout, _ = p.communicate(timeout=120)
        out.append(json.loads(stdout))
    return out


def _window(pid: int, watch: HeartbeatWatch, seconds: float, start=None) -> dict:
    """gcsd's CPU and the heartbeats over `seconds`: from when the load processes begin (or now)."""
    start_at, procs = start() if start else (time.time(), [])
    time.sleep(max(0.0, start_at - time.time()))
    cpu0, t0 = cpu_seconds(pid), time.monotonic()
    time.sleep(seconds)
    cpu1, t1 = cpu_seconds(pid), time.monotonic()
    results = _results(procs)
    return {"seconds": t1 - t0, "gcsd_cpu_pct": 100.0 * (cpu1 - cpu0) / (t1 - t0), "clients": results,
            **watch.window(t0, t1)}


def measure(workdir: Path, seconds: float = 10.0, env: dict | None = None) -> dict:
    udp_port, http_port = free_udp_port(), free_tcp_port()
    cfg = gcsd_config(workdir, [f'{{name: gcs, type: udp-server, address: "127.0.0.1:{udp_port}"}}'],
                      http=f"127.0.0.1:{http_port}")
    gcsd = start_gcsd(workdir, cfg, None, env)
    url = f"http://127.0.0.1:{http_port}"
    watch = None
    try:
        _wait_ready(url)
        watch = HeartbeatWatch(udp_port)
        time.sleep(2.0)  # the ground station is a peer and heartbeats flow
        res = {"idle": _window(gcsd.pid, watch, seconds)}
        log(f"[http] idle: gcsd {res['idle']['gcsd_cpu_pct']:.1f} % CPU")
        res["get"] = _window(gcsd.pid, watch, seconds, lambda: _load("get", url + ENTRY, 10, seconds, 2, env))
        res["get"]["requests_per_s"] = sum(c["requests"] / c["elapsed_s"] for c in res["get"]["clients"])
        res["get"]["errors"] = sum(c["errors"] for c in res["get"]["clients"])
        log(f"[http] GET ATTITUDE, 10 clients: {res['get']['requests_per_s']:.0f} requests/s, "
            f"gcsd {res['get']['gcsd_cpu_pct']:.0f} % CPU, {res['get']['errors']} errors")
        ws_url = url.replace("http://", "ws://") + "/v1/ws/mavlink"
        res["ws"] = _window(gcsd.pid, watch, seconds, lambda: _load("ws", ws_url, 20, seconds, 2, env))
        res["ws"]["frames_per_s"] = sum(c["frames"] for c in res["ws"]["clients"]) / res["ws"]["seconds"]
        log(f"[http] 20 WebSockets: {res['ws']['frames_per_s']:.0f} frames/s delivered, "
            f"gcsd {res['ws']['gcsd_cpu_pct']:.1f} % CPU")
        for name in ("idle", "get", "ws"):
            w = res[name]
            log(f"[http] {name}: ground station got {w['heartbeats']} HEARTBEATs, mean interval "
                f"{w['mean_interval_s'] or 0:.3f} s, largest {w['max_interval_s'] or 0:.3f} s")
        return res
    finally:
        if watch is not None:
            watch.close()
        gcsd.stop()


def table(res: dict) -> str:
    get, ws, idle = res["get"], res["ws"], res["idle"]

    def hb(w: dict) -> str:
        return f"{w['heartbeats']} HEARTBEATs, mean {w['mean_interval_s'] or 0:.3f} s, largest {w['max_interval_s'] or 0:.3f} s"

    p50 = max(c["p50_ms"] or 0 for c in get["clients"])
    p99 = max(c["p99_ms"] or 0 for c in get["clients"])
    return "\n".join([
        "HTTP API (bench/http.py)",
        (f"  GET one message, 10 clients: {get['requests_per_s']:.0f} requests/s (SPEC >= 2 000), p50 {p50:.1f} ms, "
         f"p99 {p99:.1f} ms, {get['errors']} errors; gcsd {get['gcsd_cpu_pct']:.0f} % CPU"),
        (f"  20 WebSockets, no filter: {ws['frames_per_s']:.0f} frames/s; gcsd {ws['gcsd_cpu_pct']:.1f} % CPU "
         f"(idle {idle['gcsd_cpu_pct']:.1f} %; SPEC <= 25 %)"),
        f"  ground station meanwhile: idle {hb(idle)}; GET {hb(get)}; WebSockets {hb(ws)}",
    ])


if __name__ == "__main__":
    import tempfile

    quick = "--quick" in sys.argv
    with tempfile.TemporaryDirectory(prefix="gcsd-bench-http-") as d:
        print(json.dumps(measure(Path(d), 3.0 if quick else 10.0), indent=2, default=str))
