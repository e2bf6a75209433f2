"""Mission upload and download of 1 000 items by MAVSDK on loopback: gcsd against mission_raw_server.

SPEC.md: "mission upload and download, 1 000 items, via MAVSDK: <= 1.5 s each".

Servers (each its own process, answering as sysid 1 / compid 1 on a UDP port on 127.0.0.1, one at
a time; the machine has 2 cores):

- ``gcsd``: ``python -m gcsd run`` with one ``udp-server`` channel, default stream rates, and
  ``mission: {max_items: 1000}`` (the default limit is 700, as ArduPilot's storage allows).
  Every accepted upload is written to ``state_dir/mission.waypoints`` (write, fsync, rename,
  fsync of the directory) before the ACK, so the figure includes that.
- ``MAVSDK mission_raw_server``: the ``mavsdk`` package (C++ core through ctypes) as an
  AUTOPILOT component on ``udpin://127.0.0.1:PORT`` with the ``mission_raw_server`` plugin and a
  subscription to incoming missions (it keeps the plan in memory and serves it back).

Client (the same for both, its own process: ``mavsdk-client``): MAVSDK as a GROUND_STATION on
``udpout://127.0.0.1:PORT``, ``first_autopilot``, the ``mission_raw`` plugin. One untimed warm-up
upload and download, then per repetition, after a 0.2-0.7 s pause (uniform, seeded): the wall
time of ``upload_mission(1 000 items)`` and of ``download_mission()``; the downloaded plan is
compared with the uploaded one (every field) after the timing. Item 0 is the vehicle's home
(gcsd serves item 0 as home, as ArduPilot does), items 1..999 NAV_WAYPOINTs with distinct
coordinates, altitudes and params, exactly one item with current = 1 (MAVSDK requires it).

    python -m bench mission           # through bench/run.py (the table at the end)
    python bench/mission.py           # this measurement alone, with its own table
"""

from __future__ import annotations

import json
import os
import random
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

if __package__ in (None, ""):  # run as a script: python bench/mission.py
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench import mavsdk_peer, report
from bench.routers import Launched, _launch, free_udp_port, gcsd_config, udp_port_bound

TOTAL = 1000
SPEC_TARGET_S = 1.5
HOME = (-353632620, 1491652370, 584.0)  # gcsd's default home: item 0 comes back as this
PAUSE_S = (0.2, 0.7)
PAUSE_SEED = 1
THIS = Path(__file__).resolve()
REPO = THIS.parent.parent


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def plan_fields(total: int = TOTAL) -> list[tuple]:
    """(seq, frame, command, current, autocontinue, p1..p4, x, y, z, mission_type) per item."""
    items = [(0, 0, 16, 1, 1, 0.0, 0.0, 0.0, 0.0, HOME[0], HOME[1], HOME[2], 0)]
    for i in range(1, total):
        items.append((i, 6, 16, 0, 1, float(i % 7), 2.0, 0.0, 0.0, HOME[0] + 37 * i, HOME[1] - 23 * i,
                      10.0 + (i % 200), 0))
    return items


# ------------------------------------------------------------------------------ the processes

def serve_mavsdk(port: int) -> int:
    """MAVSDK's mission_raw_server as an autopilot on udpin://127.0.0.1:port, until SIGTERM."""
    from mavsdk.plugins.mission_raw_server import MissionRawServer

    received = []
    with mavsdk_peer.node(f"udpin://127.0.0.1:{port}", autopilot=True) as mavsdk:
        server = MissionRawServer(mavsdk.server_component())
        handle = server.subscribe_incoming_mission(lambda result, plan, *_: received.append(result))
        code = mavsdk_peer.serve_until_sigterm(server, lambda: server.unsubscribe_incoming_mission(handle))
    print(f"incoming missions: {len(received)}", flush=True)
    return code


def mavsdk_client(port: int, reps: int, total: int) -> int:
    """MAVSDK's mission_raw against the autopilot on port; prints one JSON line."""
    from mavsdk.plugins.mission_raw import MissionItem, MissionRaw

    fields = plan_fields(total)
    items = [MissionItem(*f) for f in fields]

    def body(system, out: dict) -> None:
        mission = MissionRaw(system)
        mission.upload_mission(items)
        mission.download_mission()
        pauses = random.Random(PAUSE_SEED)
        for _ in range(reps):
            time.sleep(pauses.uniform(*PAUSE_S))
            t0 = time.perf_counter()
            mission.upload_mission(items)
            t1 = time.perf_counter()
            got = mission.download_mission()
            t2 = time.perf_counter()
            out["upload_s"].append(t1 - t0)
            out["download_s"].append(t2 - t1)
            back = [(g.seq, g.frame, g.command, g.current, g.autocontinue, g.param1, g.param2, g.param3,
                     g.param4, g.x, g.y, g.z, g.mission_type) for g in got]
            differing = int(len(back) != len(fields)) + sum(a != b for a, b in zip(back, fields))
            out["mismatches"].append(differing)
        mission.destroy()

    return mavsdk_peer.client_run(port, body, {"upload_s": [], "download_s": [], "mismatches": []})


# ---------------------------------------------------------------------------------- measuring

@dataclass
class ServerResult:
    name: str
    upload_s: list[float] = field(default_factory=list)
    download_s: list[float] = field(default_factory=list)
    mismatches: list[int] = field(default_factory=list)
    error: str | None = None
    stop: str = ""

    @property
    def upload_median_s(self) -> float | None:
        return statistics.median(self.upload_s) if self.upload_s else None

    @property
    def download_median_s(self) -> float | None:
        return statistics.median(self.download_s) if self.download_s else None

    @property
    def upload_worst_s(self) -> float | None:
        return max(self.upload_s) if self.upload_s else None

    @property
    def download_worst_s(self) -> float | None:
        return max(self.download_s) if self.download_s else None


def _wait_ready(server: Launched, port: int, pattern: str | None, timeout_s: float = 15.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if not server.alive():
            raise RuntimeError(f"{server.name} exited with code {server.popen.returncode}: {server.tail()}")
        text = server.log_path.read_text(errors="replace") if server.log_path.exists() else ""
        if (pattern is None or pattern in text) and udp_port_bound(port):
            return
        time.sleep(0.05)
    raise TimeoutError(f"{server.name} not ready within {timeout_s} s: {server.tail()}")


def _run(name: str, launch, port: int, ready: str | None, reps: int, total: int, workdir: Path,
         env: dict) -> ServerResult:
    res = ServerResult(name)
    server = launch()
    try:
        _wait_ready(server, port, ready)
        argv = [sys.executable, str(THIS), "mavsdk-client", str(port), str(reps), str(total)]
        done = subprocess.run(argv, capture_output=True, text=True, timeout=60 + 20 * reps, cwd=workdir,
                              env=env, check=False)
        (workdir / f"mission-client-{port}.log").write_text(done.stdout + done.stderr)
        line = next((ln for ln in done.stdout.splitlines() if ln.startswith("RESULT ")), None)
        if line is None:
            raise RuntimeError(f"MAVSDK client gave no result (exit {done.returncode})")
        data = json.loads(line[7:])
        res.upload_s, res.download_s = data["upload_s"], data["download_s"]
        res.mismatches = data["mismatches"]
        res.error = data.get("error")
        if res.upload_s:
            log(f"[mission] {name}: upload median {res.upload_median_s * 1000:.1f} ms, download median "
                f"{res.download_median_s * 1000:.1f} ms over {len(res.upload_s)}; plans differing: "
                f"{sum(bool(m) for m in res.mismatches)}")
        if res.error:
            log(f"[mission] {name}: {res.error}")
    except (TimeoutError, RuntimeError, subprocess.TimeoutExpired) as exc:
        res.error = str(exc)
        log(f"[mission] {name} FAILED: {exc}")
    finally:
        res.stop = server.stop()
    return res


def measure(workdir: Path, reps: int = 10, env: dict | None = None,
            total: int = TOTAL) -> dict[str, ServerResult]:
    """gcsd then MAVSDK's mission_raw_server, each driven by the same MAVSDK client."""
    env = dict(os.environ if env is None else env)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    results = {}

    port = free_udp_port()
    cfg = gcsd_config(workdir, [f'{{name: gcs, type: udp-server, address: "127.0.0.1:{port}"}}'],
                      extra=f"mission: {{max_items: {total}}}")
    log(f"[mission] gcsd: MAVSDK mission_raw uploads and downloads {total} items, {reps} times")
    argv = [sys.executable, "-m", "gcsd", "run", "-c", str(cfg)]
    results["gcsd"] = _run("gcsd", lambda: _launch("gcsd", argv, workdir, env), port, None, reps, total,
                           workdir, env)

    port = free_udp_port()
    log(f"[mission] MAVSDK mission_raw_server: the same client, {reps} times")
    argv = [sys.executable, str(THIS), "serve-mavsdk", str(port)]
    results["mavsdk"] = _run("MAVSDK mission_raw_server",
                             lambda: _launch("mission-server", argv, workdir, env),
                             port, "ready", reps, total, workdir, env)
    return results


# ------------------------------------------------------------------------------------- output

def table(results: dict[str, ServerResult]) -> str:
    g, m = results.get("gcsd"), results.get("mavsdk")

    def ms(r, attr):
        v = getattr(r, attr) if r else None
        return None if v is None else v * 1000

    target_ms = SPEC_TARGET_S * 1000
    rows = [
        (f"mission {label}, {TOTAL} items, MAVSDK mission_raw", ms(g, attr), ms(m, attr), "lo",
         f"<= {target_ms:.0f}", lambda v: v <= target_ms)
        for label, attr in (("upload, median (ms)", "upload_median_s"), ("upload, worst (ms)", "upload_worst_s"),
                            ("download, median (ms)", "download_median_s"),
                            ("download, worst (ms)", "download_worst_s"))
    ]
    notes = []
    for r in (g, m):
        if r is None:
            continue
        if r.error:
            notes.append(f"{r.name}: {r.error}")
        if r.upload_s:
            ups = ", ".join(f"{t * 1000:.0f}" for t in r.upload_s)
            downs = ", ".join(f"{t * 1000:.0f}" for t in r.download_s)
            differing = sum(bool(x) for x in r.mismatches)
            notes.append(f"{r.name}: uploads {ups} ms; downloads {downs} ms; downloaded plan differing from "
                         f"the uploaded one: {differing} of {len(r.mismatches)}; {r.stop}")
    return report.comparison_table("MAVSDK mission_raw_server", rows, notes)


def main(argv: list[str]) -> int:
    if argv and argv[0] == "serve-mavsdk":
        return serve_mavsdk(int(argv[1]))
    if argv and argv[0] == "mavsdk-client":
        return mavsdk_client(int(argv[1]), int(argv[2]), int(argv[3]))
    import argparse
    import shutil
    import tempfile

    p = argparse.ArgumentParser(prog="python bench/mission.py", description=__doc__.split("\n")[0])
    p.add_argument("--reps", type=int, default=10, help="uploads and downloads per server (default 10)")
    p.add_argument("--items", type=int, default=TOTAL, help=f"items per plan (default {TOTAL})")
    p.add_argument("--keep", action="store_true", help="keep the temporary directory (configs, logs)")
    a = p.parse_args(argv)
    workdir = Path(tempfile.mkdtemp(prefix="gcsd-bench-mission-"))
    try:
        results = measure(workdir, a.reps, total=a.items)
    finally:
        if a.keep:
            log(f"kept {workdir}")
        else:
            shutil.rmtree(workdir, ignore_errors=True)
    print(table(results))
    return 1 if any(r.error for r in results.values()) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
