"""A companion's real load (issue 29; SPEC.md "Performance"): CPU per routed packet at 200, 1 000
and 10 000 packets/s and at each router's best lossless rate, the CPU of a core at 200/s over
30 s and the resident memory after it, a companion gcsd with its defaults against mavlink-router
(the binary from GCSD_MAVLINK_ROUTER) in one run, and the same gcsd with GCSD_PURE_PYTHON=1.

Run: ``python -m bench companion_load`` (about 12 minutes; ``--quick`` about 3). ``--routers``
as usual (gcsd and mavlink-router; the pure-Python gcsd comes with gcsd).

The routing harness of bench/README.md (sender -> channel/endpoint `a` -> `b` -> receiver,
COMMAND_LONG from 200/190 to 250/1, one frame per datagram). gcsd is a companion with its
defaults: ``vehicle: {type: companion}``, the HTTP API on (on a free port), two udp-server
channels `a` and `b` with nothing else set (its streams are the companion's own). mavlink-router
has the two UDP server endpoints of the routing benchmark. For each router in turn (a new
process each): fixed-rate trials at 1 000 and 10 000/s (TRIAL_S), then 200/s for CPU_S, then the
throughput search of the routing benchmark for its best lossless rate. CPU per packet = the
router's utime + stime over the trial (/proc, from just before the first packet to the last one's
arrival) / packets received; the 200/s row is that CPU over the window as % of one core; RSS is
VmRSS after the 200/s window. Ratios are gcsd / mavlink-router of the same run.
"""

from __future__ import annotations

import os

from bench import measure
from bench.measure import Path, log
from bench.routers import (
    cpu_seconds,
    free_udp_port,
    gcsd_config,
    proc_status_kb,
    routing_mavlink_router_config,
    start_gcsd,
    start_mavlink_router,
)

RATES = (1000, 10000)
TRIAL_S, QUICK_TRIAL_S = 10.0, 3.0
CPU_RATE = 200
CPU_S, QUICK_CPU_S = 30.0, 10.0
KINDS = ("gcsd", "gcsd-pure", "mavlink-router")


def _path(runner, kind: str) -> Path:
    s, r = runner.peers()
    port_a, port_b = free_udp_port(), free_udp_port()
    if kind == "mavlink-router":
        router = start_mavlink_router(runner.workdir, runner.mavlink_router,
                                      routing_mavlink_router_config(runner.workdir, port_a, port_b))
    else:
        cfg = gcsd_config(runner.workdir, [
            f'{{name: a, type: udp-server, address: "127.0.0.1:{port_a}"}}',
            f'{{name: b, type: udp-server, address: "127.0.0.1:{port_b}"}}',
        ], extra="vehicle: {type: companion}")
        env = dict(runner.gcsd_env or os.environ)
        if kind == "gcsd-pure":
            env["GCSD_PURE_PYTHON"] = "1"
        else:
            env.pop("GCSD_PURE_PYTHON", None)
        router = start_gcsd(runner.workdir, cfg, None, env)
    s.call("dest", ("127.0.0.1", port_a))
    r.call("peer", ("127.0.0.1", port_b), False)
    path = Path(kind, s, r, runner.seqs, router, {"router-in": port_a, "router-b": port_b, "receiver": r.port},
                idle_threshold_pct=runner.a.idle_threshold, idle_wait_s=runner.a.idle_wait)
    measure.wait_path_ready(path)
    return path


def _fixed(path: Path, rate: float, duration_s: float) -> dict:
    pid = path.router.pid
    measure.wait_idle(path)
    c0 = cpu_seconds(pid)
    t = measure.run_trial(path, rate, duration_s)
    cpu_s = cpu_seconds(pid) - c0
    log(f"  [companion_load {path.name}] {t.line()}")
    return {"rate": rate, "received": t.received, "lost": t.lost, "cpu_s": cpu_s,
            "us_per_packet": cpu_s / t.received * 1e6 if t.received else None,
            "cpu_pct": t.cpu_pct.get("router"), "other_cpu_pct": t.other_cpu_pct}


def measure_one(runner, kind: str) -> dict:
    quick = runner.a.quick
    path = _path(runner, kind)
    res: dict = {}
    try:
        for rate in RATES:
            res[rate] = _fixed(path, rate, QUICK_TRIAL_S if quick else TRIAL_S)
        window = QUICK_CPU_S if quick else CPU_S
        f = _fixed(path, CPU_RATE, window)
        f["core_pct"] = 100.0 * f["cpu_s"] / window
        res[CPU_RATE] = f
        res["rss_mb"] = (proc_status_kb(path.router.pid, "VmRSS") or 0) / 1024
        best = measure.search_throughput(path, 1.0 if quick else 5.0, 0.2 if quick else 0.05, confirm=not quick)
        b = best.best
        res["best"] = {"rate": best.rate, "confirmed": best.confirmed, "sender_limited": best.sender_limited,
                       "us_per_packet": (b.cpu_pct["router"] / 100 * (b.offered / b.rate) / b.received * 1e6
                                         if b is not None and b.received else None)}
    finally:
        res["stop"] = path.router.stop()
    return res


def measure_load(runner) -> dict:
    kinds = [k for k in KINDS if (k.startswith("gcsd") and "gcsd" in runner.a.routers)
             or (k == "mavlink-router" and "mavlink-router" in runner.a.routers and runner.mavlink_router)]
    return {k: measure_one(runner, k) for k in kinds}


def _fmt(v, spec: str) -> str:
    return "n/a" if v is None else format(v, spec)


def table(res: dict) -> str:
    kinds = [k for k in KINDS if k in res]
    rows = [(f"CPU per packet at {r} pkt/s (us)", lambda x, r=r: x[r]["us_per_packet"], ".1f", 1.0)
            for r in RATES]
    rows += [("best lossless rate (pkt/s)", lambda x: x["best"]["rate"], ".0f", None),
             ("CPU per packet at its best rate (us)", lambda x: x["best"]["us_per_packet"], ".2f", 1.0),
             (f"CPU at {CPU_RATE} pkt/s (% of a core)", lambda x: x[CPU_RATE]["core_pct"], ".2f", 1.5),
             (f"CPU per packet at {CPU_RATE} pkt/s (us)", lambda x: x[CPU_RATE]["us_per_packet"], ".1f", None),
             ("RSS after it (MB)", lambda x: x["rss_mb"], ".1f", None)]
    head = "| what | " + " | ".join(kinds) + (" | gcsd / mavlink-router | pure / mavlink-router | target |"
                                               if "mavlink-router" in kinds else " |")
    out = ["Companion load (bench/companion_load.py): a companion gcsd with its defaults, side by side", head,
           "|---" * (head.count("|") - 1) + "|"]
    for name, get, spec, limit in rows:
        vals = {k: get(res[k]) for k in kinds}
        line = f"| {name} | " + " | ".join(_fmt(vals[k], spec) for k in kinds) + " |"
        if "mavlink-router" in kinds:
            ref = vals["mavlink-router"]
            for k in ("gcsd", "gcsd-pure"):
                v = vals.get(k)
                line += f" {v / ref:.2f}x |" if v is not None and ref else " n/a |"
            line += (" <= 40 MB |" if name.startswith("RSS") else f" <= {limit}x |" if limit else " |")
        out.append(line)
    lost = ", ".join(f"{k} {sum(res[k][r]['lost'] for r in (*RATES, CPU_RATE))}" for k in kinds)
    out.append(f"packets lost in the fixed-rate trials: {lost}")
    return "\n".join(out)
