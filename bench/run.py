"""gcsd benchmark runner: routing throughput and latency against mavlink-router and MAVProxy, and
one vehicle's cost.

    python -m bench                      # everything (about 5 minutes on an idle machine)
    python -m bench --quick              # smoke run (about 1 minute)
    python -m bench throughput latency   # just these; also: harness, vehicle, params, param_flood, mission,
                                         # signing, swarm, http, ftp, fleet (the MQTT fleet, bench/fleet.py),
                                         # lossy (mission upload time vs loss, bench/lossy.py),
                                         # logs (flight-log download and capture, bench/logs.py),
                                         # companion (filters and rate caps, bench/companion.py),
                                         # routes (20 against 250 learned routes, bench/routes.py)
    python -m bench --routers mavproxy   # only some routers (default gcsd,mavlink-router,mavproxy)

mavlink-router is the binary in $GCSD_MAVLINK_ROUTER (or mavlink-routerd on PATH); without it the
bench says so and measures the others.

Progress goes to stderr; the result table to stdout; ``--json FILE`` saves every figure and trial.
See bench/README.md for the method.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, is_dataclass
from pathlib import Path as FsPath

if __package__ in (None, ""):  # run as a script: python bench/run.py
    sys.path.insert(0, str(FsPath(__file__).resolve().parent.parent))

from bench import companion as bench_companion
from bench import companion_load as bench_companion_load
from bench import fleet as bench_fleet
from bench import ftp as bench_ftp
from bench import http as bench_http
from bench import logs as bench_logs
from bench import lossy as bench_lossy
from bench import measure
from bench import mission as bench_mission
from bench import param_flood as bench_param_flood
from bench import params as bench_params
from bench import routes as bench_routes
from bench import signing as bench_signing
from bench import swarm as bench_swarm
from bench.measure import Path, SeqAllocator, log
from bench.peers import start_receiver, start_sender
from bench.report import routers_table
from bench.routers import (
    export_gcsd_rev,
    free_udp_port,
    gcsd_available,
    gcsd_config,
    gcsd_env,
    mavlink_router_binary,
    mavlink_router_version,
    routing_gcsd_config,
    routing_mavlink_router_config,
    start_gcsd,
    start_mavlink_router,
    start_mavproxy,
)

WHAT = ("harness", "throughput", "latency", "vehicle", "params", "param_flood", "mission", "signing", "swarm", "http",
        "ftp", "fleet", "lossy", "logs", "companion", "routes", "companion_load")
ROUTERS = {"gcsd": "gcsd", "mavlink-router": "mavlink-router", "mavproxy": "MAVProxy"}  # name -> column
LATENCY_RATE = 1000


def machine() -> dict:
    model = ""
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"nproc": os.cpu_count(), "cpu": model, "python": platform.python_version(),
            "kernel": platform.release(), "date": time.strftime("%Y-%m-%d %H:%M:%S"), "gcsd_commit": _commit()}


def _commit() -> str:
    """HEAD of the repository bench/ lives in, with '+dirty' if src/ has uncommitted changes."""
    root = FsPath(__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True,
                              text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "src"], cwd=root, capture_output=True,
                               text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"
    return (head or "unknown") + ("+dirty" if dirty else "")


def parse_args(argv):
    p = argparse.ArgumentParser(prog="python -m bench", description=__doc__.split("\n")[0])
    p.add_argument("what", nargs="*", metavar="WHAT",
                   help=f"measurements to run: {', '.join(WHAT)} or all (default all)")
    p.add_argument("--quick", action="store_true", help="short trials, coarse search: a smoke run")
    p.add_argument("--routers", default="gcsd,mavlink-router,mavproxy",
                   help="comma list of gcsd, mavlink-router, mavproxy (default all three)")
    p.add_argument("--trial-s", type=float, help="seconds per throughput trial (5; quick 1)")
    p.add_argument("--precision", type=float, help="bisection stops within this fraction (0.05; quick 0.2)")
    p.add_argument("--latency-s", type=float, help="seconds of latency sampling (10; quick 2)")
    p.add_argument("--cpu-s", type=float, help="seconds of the vehicle CPU window (30; quick 5)")
    p.add_argument("--start-samples", type=int, help="launches timed to first HEARTBEAT (5; quick 1)")
    p.add_argument("--profile-gcsd", metavar="DIR",
                   help="run gcsd under cProfile; write DIR/gcsd-routing.prof and DIR/gcsd-vehicle.prof")
    p.add_argument("--idle-threshold", type=float, default=15.0, metavar="PCT",
                   help="before each trial wait until other processes use less than PCT%% of a core "
                        "(default 15; 0 = never wait, never repeat disturbed trials)")
    p.add_argument("--idle-wait", type=float, default=120.0, metavar="S",
                   help="wait at most S seconds for that (default 120)")
    p.add_argument("--gcsd-rev", metavar="REV",
                   help="benchmark gcsd as committed at REV (git archive of src/ into the temporary "
                        "directory, imported via PYTHONPATH) instead of the working tree")
    p.add_argument("--json", metavar="FILE", help="write all figures and trials as JSON")
    p.add_argument("--keep", action="store_true", help="keep the temporary directory (configs, logs)")
    a = p.parse_args(argv)
    what = set(a.what or ["all"])
    for w in what - {*WHAT, "all"}:
        p.error(f"unknown measurement {w!r}; choose from {', '.join(WHAT)}, all")
    a.what = set(WHAT) if "all" in what else what
    a.routers = [r.strip() for r in a.routers.split(",") if r.strip()]
    for r in a.routers:
        if r not in ROUTERS:
            p.error(f"unknown router {r!r}")
    q = a.quick
    a.trial_s = a.trial_s or (1.0 if q else 5.0)
    a.precision = a.precision or (0.2 if q else 0.05)
    a.latency_s = a.latency_s or (2.0 if q else 10.0)
    a.cpu_s = a.cpu_s or (5.0 if q else 30.0)
    a.start_samples = a.start_samples or (1 if q else 5)
    return a


def _short(text: str, limit: int = 400) -> str:
    return text if len(text) <= limit else text[: limit - 5] + " ..."


def _jsonable(x):
    if is_dataclass(x):
        return {k: _jsonable(v) for k, v in asdict(x).items() if k not in ("report", "send_stamps")}
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items() if k not in ("report", "send_stamps", "stamps")}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


class Runner:
    def __init__(self, args) -> None:
        self.a = args
        self.workdir = FsPath(tempfile.mkdtemp(prefix="gcsd-bench-"))
        self.seqs = SeqAllocator()
        self.sender = None
        self.receiver = None
        self.res: dict = {"machine": machine(), "args": {k: (sorted(v) if isinstance(v, set) else v)
                                                         for k, v in vars(args).items()}}
        self.notes: list[str] = []
        self.gcsd_env = None
        self.mavlink_router: str | None = None
        if args.gcsd_rev:
            src, commit = export_gcsd_rev(FsPath(__file__).resolve().parent.parent, args.gcsd_rev,
                                          self.workdir / "gcsd-rev")
            self.gcsd_env = gcsd_env(src)
            self.res["machine"]["gcsd_commit"] = commit + " (exported)"
            log(f"gcsd from commit {commit}, exported to {src}")

    # -------------------------------------------------------------------------------- helpers
    def peers(self):
        if self.sender is None:
            self.sender = start_sender()
            self.receiver = start_receiver()
            log(f"sender pid {self.sender.pid}, receiver pid {self.receiver.pid} "
                f"(port {self.receiver.port}, SO_RCVBUF {self.receiver.info[0]} bytes)")
        return self.sender, self.receiver

    def direct_path(self) -> Path:
        s, r = self.peers()
        s.call("dest", ("127.0.0.1", r.port))
        r.call("peer", None, False)
        return Path("direct", s, r, self.seqs, ports={"receiver": r.port},
                    idle_threshold_pct=self.a.idle_threshold, idle_wait_s=self.a.idle_wait)

    def router_path(self, name: str) -> Path:
        s, r = self.peers()
        port_a = free_udp_port()
        port_b = free_udp_port()
        if name == "gcsd":
            cfg = routing_gcsd_config(self.workdir, port_a, port_b)
            prof = self._profile("gcsd-routing.prof")
            router = start_gcsd(self.workdir, cfg, prof, self.gcsd_env)
            s.call("dest", ("127.0.0.1", port_a))
            r.call("peer", ("127.0.0.1", port_b), False)  # receiver is a udp-server client of channel b
        elif name == "mavlink-router":  # the same two UDP servers: endpoint a in, endpoint b out
            cfg = routing_mavlink_router_config(self.workdir, port_a, port_b)
            router = start_mavlink_router(self.workdir, self.mavlink_router, cfg)
            s.call("dest", ("127.0.0.1", port_a))
            r.call("peer", ("127.0.0.1", port_b), False)
        else:
            router = start_mavproxy(self.workdir, port_a, r.port)
            s.call("dest", ("127.0.0.1", port_a))
            r.call("peer", None, True)  # heartbeat back to MAVProxy's --out socket once it is seen
        ports = {"router-in": port_a, "receiver": r.port}
        if name != "mavproxy":
            ports["router-b"] = port_b
        path = Path(name, s, r, self.seqs, router, ports, idle_threshold_pct=self.a.idle_threshold,
                    idle_wait_s=self.a.idle_wait)
        took = measure.wait_path_ready(path)
        log(f"[{name}] pid {router.pid}: routing after {took:.2f} s ({' '.join(router.argv[1:])})")
        return path

    def _profile(self, filename: str):
        if not self.a.profile_gcsd:
            return None
        d = FsPath(self.a.profile_gcsd).resolve()
        d.mkdir(parents=True, exist_ok=True)
        return d / filename

    def close(self) -> None:
        for p in (self.sender, self.receiver):
            if p is not None:
                p.close()
        if self.a.keep:
            log(f"kept {self.workdir}")
        else:
            shutil.rmtree(self.workdir, ignore_errors=True)

    # ----------------------------------------------------------------------------- measurements
    def run(self) -> None:
        a = self.a
        if "gcsd" in a.routers or a.what & {"vehicle", "params", "param_flood", "mission", "signing", "ftp", "logs"}:
            ok, text = gcsd_available(self.gcsd_env)
            self.res["gcsd_version"] = text
            if not ok:
                self.notes.append(f"gcsd not runnable ({text}); its columns are n/a")
                a.routers = [r for r in a.routers if r != "gcsd"]
                a.what -= {"vehicle", "params", "param_flood", "mission", "signing", "ftp", "logs"}
                log(f"gcsd not runnable: {text}")
        if "mavlink-router" in a.routers and a.what & {"throughput", "latency", "routes", "companion_load"}:
            self.mavlink_router, how = mavlink_router_binary()
            if self.mavlink_router is None:
                self.notes.append(f"mavlink-router skipped: {how}")
                a.routers = [r for r in a.routers if r != "mavlink-router"]
            else:
                self.res["mavlink_router_version"] = f"{mavlink_router_version(self.mavlink_router)} ({how})"
            log(f"mavlink-router: {self.res.get('mavlink_router_version') or 'skipped: ' + how}")
        if a.what & {"harness", "throughput", "latency"}:
            self.harness()
        for name in a.routers:
            if a.what & {"throughput", "latency"}:
                self.routed(name)
        if "vehicle" in a.what:
            self.vehicle()
        if "params" in a.what:
            self.params()
        if "param_flood" in a.what:  # bench/param_flood.py: a second client's latency under 1 000 PARAM_SET/s
            self.res["param_flood"] = bench_param_flood.measure(self.workdir, a.quick, self.gcsd_env)
        if "mission" in a.what:
            self.mission()
        if "signing" in a.what:
            self.res["signing"] = bench_signing.measure_signing(self)
        if "http" in a.what:  # bench/http.py: the HTTP API under load, the heartbeat meanwhile
            self.res["http"] = bench_http.measure(self.workdir, 3.0 if a.quick else 10.0, self.gcsd_env)
        if "swarm" in a.what:
            self.res["swarm"] = bench_swarm.measure(self.workdir, self.a.quick, getattr(self, "gcsd_env", None))
        if "ftp" in a.what:  # bench/ftp.py: 10 MB burst read and param.pck, against MAVSDK's ftp_server
            self.res["ftp"] = bench_ftp.measure(self.workdir, self.a.quick, getattr(self, "gcsd_env", None))
        if "fleet" in a.what:  # bench/fleet.py: vehicle-side processes -> Mosquitto -> ground side
            self.res["fleet"] = bench_fleet.measure(self.workdir, self.a.quick, getattr(self, "gcsd_env", None))
        if "lossy" in a.what:  # bench/lossy.py: upload time vs loss, adaptive re-requests vs a fixed 1 s
            self.res["lossy"] = bench_lossy.measure(self.workdir, self.a.quick, getattr(self, "gcsd_env", None))
        if "companion" in a.what and "gcsd" in a.routers:  # bench/companion.py: filters and rate caps
            self.res["companion"] = bench_companion.measure_gates(self)
        if "routes" in a.what:  # bench/routes.py: 20 against 250 learned routes, gcsd and mavlink-router
            self.res["routes"] = bench_routes.measure_routes(self)
        if "companion_load" in a.what:  # bench/companion_load.py: a companion's load against mavlink-router
            self.res["companion_load"] = bench_companion_load.measure_load(self)
        if "logs" in a.what:  # bench/logs.py: 10 MB log download, capture at 921 600 baud
            self.res["logs"] = bench_logs.measure(self.workdir / "logs", self.a.quick, getattr(self, "gcsd_env", None))

    def harness(self) -> None:
        a = self.a
        path = self.direct_path()
        log("[direct] harness alone: sender -> receiver, no router")
        h = self.res.setdefault("direct", {})
        if "harness" in a.what or "throughput" in a.what:
            # only needs to show that sender and receiver outrun any router: up to 200 k/s, 2 s trials
            sr = measure.search_throughput(path, min(a.trial_s, 2.0), max(a.precision, 0.1), start_rate=25000,
                                           max_rate=200_000, confirm=False)
            h["throughput"] = sr
        if "latency" in a.what:
            h["latency"] = measure.measure_latency(path, LATENCY_RATE, a.latency_s)

    def routed(self, name: str) -> None:
        a = self.a
        r = self.res.setdefault(name, {})
        try:
            path = self.router_path(name)
        except (TimeoutError, measure.RouterDied) as exc:
            r["error"] = str(exc)
            self.notes.append(_short(f"{name}: {exc}"))
            log(f"[{name}] FAILED: {exc}")
            return
        try:
            if "throughput" in a.what:
                cap = self.res.get("direct", {}).get("throughput")
                max_rate = cap.rate if cap and cap.rate else 200_000
                sr = measure.search_throughput(path, a.trial_s, a.precision, max_rate=max_rate,
                                               confirm=not a.quick)
                r["throughput"] = sr
                if cap and sr.rate >= cap.rate:
                    self.notes.append(f"{name}: routed rate reached the harness capacity; figure is a lower bound")
            if "latency" in a.what:
                r["latency"] = measure.measure_latency(path, LATENCY_RATE, a.latency_s)
        except (measure.RouterDied, TimeoutError) as exc:
            r["error"] = str(exc)
            self.notes.append(_short(f"{name}: {exc}"))
            log(f"[{name}] FAILED: {exc}")
        finally:
            r["stop"] = path.router.stop()
            log(f"[{name}] {r['stop']}")

    def vehicle(self) -> None:
        a = self.a
        port = free_udp_port()
        cfg = gcsd_config(self.workdir, [f'{{name: gcs, type: udp-server, address: "127.0.0.1:{port}"}}'])
        prof = self._profile("gcsd-vehicle.prof")
        log(f"[gcsd] one vehicle, default rates, two ground stations; {a.start_samples} timed start(s), "
            f"{a.cpu_s:.0f} s CPU window")
        try:
            self.res.setdefault("gcsd", {})["vehicle"] = measure.measure_vehicle(
                lambda: start_gcsd(self.workdir, cfg, prof, self.gcsd_env), port, a.cpu_s, a.start_samples,
                idle_threshold_pct=a.idle_threshold, idle_wait_s=a.idle_wait)
        except RuntimeError as exc:
            self.notes.append(_short(f"gcsd vehicle: {exc}"))
            log(f"[gcsd] vehicle FAILED: {exc}")

    def params(self) -> None:
        """Full PARAM_REQUEST_LIST download, 1 000 parameters: gcsd against MAVSDK's param_server."""
        self.res["params"] = bench_params.measure(self.workdir, reps=3 if self.a.quick else 10,
                                                  env=getattr(self, "gcsd_env", None))
        self.notes += [f"params: {e}" for e in (r.error for r in self.res["params"].values()) if e]

    def mission(self) -> None:
        """1 000-item mission upload and download by MAVSDK: gcsd against MAVSDK's mission_raw_server."""
        self.res["mission"] = bench_mission.measure(self.workdir, reps=3 if self.a.quick else 10,
                                                    env=getattr(self, "gcsd_env", None))
        self.notes += [f"mission: {e}" for e in (r.error for r in self.res["mission"].values()) if e]

    # ----------------------------------------------------------------------------------- output
    def table(self) -> str:
        g, d = self.res.get("gcsd", {}), self.res.get("direct", {})
        routed = {name: self.res.get(name, {}) for name in ROUTERS}

        def each(f) -> dict[str, float | None]:
            return {name: f(x) for name, x in routed.items()}

        def thr(x):
            t = x.get("throughput")
            return None if t is None else t.rate

        def tcpu(x):
            t = x.get("throughput")
            return None if t is None else t.router_cpu_pct

        def us_per_packet(x):  # CPU per routed packet at the best clean rate
            t = x.get("throughput")
            return None if t is None or not t.rate or t.router_cpu_pct is None else t.router_cpu_pct / 100 / t.rate * 1e6

        def lat(attr):
            return each(lambda x: None if x.get("latency") is None else getattr(x["latency"], attr))

        def vs_router(limit: float, better: str):  # SPEC: relative to mavlink-router in the same run
            def check(v):
                gv, rv = v.get("gcsd"), v.get("mavlink-router")
                if rv is None:
                    return None
                return gv >= limit * rv if better == "hi" else gv <= limit * rv
            return check

        def throughput_ok(v):
            rel = vs_router(1.5, "hi")(v)
            return v["gcsd"] >= 40000 and rel is not False

        veh = g.get("vehicle")
        starts = sorted(veh.start_to_heartbeat_s) if veh else []
        only_gcsd = lambda v: {"gcsd": v}
        rows = [
            ("packets routed between two UDP channels, no loss (pkt/s)", each(thr), "hi",
             ">= 40000 and >= 1.5x mavlink-router", throughput_ok),
            ("  router CPU at that rate (% of one core)", each(tcpu), None, "", None),
            ("  router CPU per routed packet (us)", each(us_per_packet), "lo", "<= 1.5x mavlink-router's",
             vs_router(1.5, "lo")),
            (f"latency through router, p50, {LATENCY_RATE} pkt/s (ms)", lat("p50_ms"), "lo", "", None),
            (f"latency through router, p99, {LATENCY_RATE} pkt/s (ms)", lat("p99_ms"), "lo", "", None),
            ("latency added by routing, p50 (ms)", lat("added_p50_ms"), "lo", "", None),
            (f"latency added by routing, p99, {LATENCY_RATE} pkt/s (ms)", lat("added_p99_ms"), "lo", "<= 1",
             lambda v: v["gcsd"] <= 1.0),
            ("CPU, one vehicle, default rates, 2 GCS (% of one core)", only_gcsd(veh.cpu_pct if veh else None), None,
             "<= 3", lambda v: v["gcsd"] <= 3.0),
            ("resident memory, one vehicle (MB)", only_gcsd(veh.rss_mb if veh else None), None, "<= 60",
             lambda v: v["gcsd"] <= 60.0),
            ("start to first HEARTBEAT, median (s)", only_gcsd(starts[len(starts) // 2] if starts else None), None,
             "<= 1", lambda v: v["gcsd"] <= 1.0),
            ("start to first HEARTBEAT, worst (s)", only_gcsd(starts[-1] if starts else None), None, "<= 1",
             lambda v: v["gcsd"] <= 1.0),
        ]
        shown = {name: label for name, label in ROUTERS.items()
                 if name == "gcsd" or routed[name].get("throughput") or routed[name].get("latency")}
        out = routers_table(shown, rows).splitlines()

        mc = self.res["machine"]
        out.insert(0, f"gcsd bench, {mc['date']}, {mc['nproc']} CPUs ({mc['cpu']}), Python {mc['python']}, "
                      f"{'quick' if self.a.quick else 'full'} run, gcsd at {mc['gcsd_commit']}"
                      + (f" ({self.res['gcsd_version']})" if self.res.get("gcsd_version") else ""))
        out.insert(1, "")
        extra = []
        dt = d.get("throughput")
        if dt is not None:
            extra.append(f"harness alone (sender -> receiver, no router): {dt.rate:,.0f} pkt/s without loss"
                         + (" (sender-limited)" if dt.sender_limited else ""))
        if d.get("latency") is not None:
            dl = d["latency"]
            extra.append(f"direct-path latency at {LATENCY_RATE} pkt/s, alone: p50 {dl.p50_ms:.3f} ms, "
                         f"p99 {dl.p99_ms:.3f} ms")
        for name, x in ((ROUTERS[n], routed[n]) for n in ROUTERS):
            t = x.get("latency")
            if t is not None and t.direct_p50_ms is not None:
                extra.append(f"{name} latency: baseline (direct path, in blocks alternating with the routed ones) "
                             f"p50 {t.direct_p50_ms:.3f} ms, p99 {t.direct_p99_ms:.3f} ms; {t.blocks} block pairs, "
                             f"{t.disturbed_blocks} discarded as disturbed; routed max {t.max_ms:.3f} ms")
        for name, x in ((ROUTERS[n], routed[n]) for n in ROUTERS):
            t = x.get("throughput")
            if t is not None and t.sender_limited:
                extra.append(f"{name}: throughput search stopped by the sender (figure is a lower bound)")
            if t is not None and not self.a.quick and not t.confirmed and not t.sender_limited:
                extra.append(f"{name}: no rate stayed clean over a {2 * self.a.trial_s:.0f} s confirmation "
                             f"trial; the figure is the best {self.a.trial_s:.0f} s trial")
        if veh is not None:
            extra.append(f"vehicle: {', '.join(f'{v:.1f}' for v in veh.msgs_per_s)} msgs/s to the two ground "
                         f"stations; VmHWM {veh.hwm_mb:.1f} MB; start samples "
                         f"{', '.join(f'{s:.3f}' for s in veh.start_to_heartbeat_s)} s (UDP port bound after "
                         f"{', '.join(f'{s:.3f}' for s in veh.port_bound_s)} s); gcsd {veh.stop}")
        others = []
        for x in (*routed.values(), d):
            if x.get("throughput") is not None:
                others += [t.other_cpu_pct for t in x["throughput"].trials]
            if x.get("latency") is not None:
                others.append(x["latency"].other_cpu_pct)
        if others:
            extra.append(f"CPU used by processes outside the benchmark during trials: max {max(others):.0f} %, "
                         f"median {sorted(others)[len(others) // 2]:.0f} % of one core"
                         + (" -- the machine was not idle, figures are pessimistic" if max(others) > 10 else ""))
        extra += self.notes
        if extra:
            out += ["", *extra]
        if self.res.get("params"):
            out += ["", "Parameters: full list by PARAM_REQUEST_LIST on loopback, gcsd against MAVSDK's "
                    "param_server (bench/params.py)", "", bench_params.table(self.res["params"])]
        if self.res.get("param_flood"):
            out += ["", bench_param_flood.table(self.res["param_flood"])]
        if self.res.get("mission"):
            out += ["", "Missions: 1 000 items uploaded and downloaded by MAVSDK mission_raw, gcsd against MAVSDK's "
                    "mission_raw_server (bench/mission.py)", "", bench_mission.table(self.res["mission"])]
        if self.res.get("signing"):
            out += ["", bench_signing.table(self.res["signing"])]
        if self.res.get("swarm"):
            out += ["", bench_swarm.table(self.res["swarm"])]
        if self.res.get("http"):
            out += ["", bench_http.table(self.res["http"])]
        if self.res.get("ftp"):
            out += ["", "FTP: 10 MB burst read and @PARAM/param.pck, gcsd against MAVSDK's ftp_server (bench/ftp.py)",
                    "", bench_ftp.table(self.res["ftp"])]
        if self.res.get("fleet"):
            out += ["", bench_fleet.table(self.res["fleet"])]
        if self.res.get("lossy"):
            out += ["", bench_lossy.table(self.res["lossy"])]
        if self.res.get("companion"):
            out += ["", bench_companion.table(self.res["companion"])]
        if self.res.get("routes"):
            out += ["", bench_routes.table(self.res["routes"])]
        if self.res.get("companion_load"):
            out += ["", bench_companion_load.table(self.res["companion_load"])]
        if self.res.get("logs"):
            out += ["", "Flight logs: 10 MB log download (LOG_REQUEST_DATA), capture at 921 600 baud (bench/logs.py)",
                    "", bench_logs.table(self.res["logs"])]
        return "\n".join(out)


def main(argv=None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    runner = Runner(args)
    t0 = time.monotonic()
    try:
        runner.run()
    except KeyboardInterrupt:
        log("interrupted")
    finally:
        runner.close()
    runner.res["elapsed_s"] = time.monotonic() - t0
    end_commit = _commit()
    if not args.gcsd_rev and end_commit != runner.res["machine"]["gcsd_commit"]:
        runner.notes.append(f"gcsd changed during the run: {runner.res['machine']['gcsd_commit']} at the start, "
                            f"{end_commit} at the end")
    print(runner.table())
    if args.json:
        FsPath(args.json).write_text(json.dumps(_jsonable(runner.res), indent=2) + "\n")
        log(f"wrote {args.json}")
    failed = [n for n in args.routers if "error" in runner.res.get(n, {})]
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
