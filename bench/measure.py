"""The measurements: zero-loss routing throughput, added latency, and one vehicle's CPU/RSS/start time.

A ``Path`` is one way from the sender to the receiver: ``direct`` (no router: harness capacity and
latency baseline), or through gcsd / MAVProxy.  A trial offers ``rate * duration`` packets with fresh
sequence numbers, waits until the receiver has them all or has seen nothing new for 0.5 s, and
records loss, duplicates, reordering and the CPU used by router, sender and receiver.

The machine is shared: before each trial we wait (up to ``idle_wait_s``) until processes outside the
benchmark use less than ``idle_threshold_pct`` of a core, and a lossy trial during which they used
more than 20 % is repeated (up to 3 times); a latency sample so disturbed is repeated likewise and
the least disturbed one kept.  Every trial records how much CPU others used.

Throughput search: start at ``start_rate`` and double while a trial loses nothing; after the first
loss, bisect between the best clean rate and the lowest lossy one until they are within
``precision``; then (unless quick) confirm the best rate with a trial twice as long, stepping down
5 % (10 % if more than 1 % was lost) per failure, up to 10 times; if none is clean the figure is
the best short-trial rate, marked unconfirmed.  A trial where the sender could not keep the offered
rate ends the search (the figure is then a lower bound, marked "sender-limited").
"""

from __future__ import annotations

import math
import os
import select
import socket
import statistics
import sys
import time
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from bench.frames import MAX_SEQ
from bench.peers import Peer
from bench.routers import Launched, cpu_seconds, machine_busy_s, proc_status_kb, udp_drops, udp_port_bound


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


class SeqAllocator:
    def __init__(self) -> None:
        self.next = 0

    def take(self, n: int) -> int:
        lo = self.next
        self.next += n
        if self.next >= MAX_SEQ:
            raise RuntimeError("ran out of 24-bit sequence numbers; run fewer trials per invocation")
        return lo


@dataclass
class Path:
    name: str
    sender: Peer
    receiver: Peer
    seqs: SeqAllocator
    router: Launched | None = None
    ports: dict[str, int] = field(default_factory=dict)  # socket label -> local port, for drop counts
    idle_threshold_pct: float = 15.0  # wait before a trial while other processes use more CPU than this
    idle_wait_s: float = 120.0  # ... but at most this long

    def pids(self) -> dict[str, int]:
        pids = {"sender": self.sender.pid, "receiver": self.receiver.pid, "parent": os.getpid()}
        if self.router is not None:
            pids["router"] = self.router.pid
        return pids

    def check_router(self) -> None:
        if self.router is not None and not self.router.alive():
            raise RouterDied(f"{self.router.name} exited with code {self.router.popen.returncode}:\n"
                             f"{self.router.tail()}")


class RouterDied(RuntimeError):
    pass


@dataclass
class Trial:
    rate: float
    offered: int
    received: int
    dup: int
    reorder: int
    stale: int
    sender_rate: float
    sender_max_lag_s: float
    cpu_pct: dict[str, float]
    other_cpu_pct: float = 0.0  # CPU used by processes outside the benchmark during the trial
    drops: dict[str, int] = field(default_factory=dict)
    report: dict = field(repr=False, default_factory=dict)
    send_stamps: dict | None = field(repr=False, default=None)

    @property
    def lost(self) -> int:
        return self.offered - self.received

    @property
    def clean(self) -> bool:
        return self.lost == 0 and self.dup == 0

    def sender_limited(self) -> bool:
        return self.sender_rate < 0.97 * self.rate

    def line(self) -> str:
        cpu = " ".join(f"{k} {v:.0f}%" for k, v in self.cpu_pct.items() if k != "parent")
        if self.other_cpu_pct >= 5:
            cpu += f" OTHER PROCESSES {self.other_cpu_pct:.0f}%"
        drops = " ".join(f"{k} {v}" for k, v in self.drops.items() if v)
        return (f"rate {self.rate:>8.0f}/s offered {self.offered:>7} lost {self.lost:>6} dup {self.dup} "
                f"reorder {self.reorder} sent at {self.sender_rate:>8.0f}/s | cpu {cpu}"
                + (f" | socket drops: {drops}" if drops else ""))


def other_cpu_pct(pids, interval_s: float = 0.5) -> float:
    """CPU % (of one core) used by processes other than ``pids`` over ``interval_s``."""
    ours0 = sum(cpu_seconds(p) for p in pids)
    m0, w0 = machine_busy_s(), time.monotonic()
    time.sleep(interval_s)
    ours1 = sum(cpu_seconds(p) for p in pids)
    m1, w1 = machine_busy_s(), time.monotonic()
    return max(0.0, 100.0 * ((m1 - m0) - (ours1 - ours0)) / (w1 - w0))


def wait_idle(path: Path) -> None:
    """Wait (up to path.idle_wait_s) until other processes use less than path.idle_threshold_pct."""
    wait_idle_pids(list(path.pids().values()), path.idle_threshold_pct, path.idle_wait_s, path.name)


def wait_idle_pids(pids: list[int], threshold_pct: float, max_wait_s: float, label: str) -> float:
    """Wait until processes other than ``pids`` use less than threshold_pct; returns their last %."""
    if threshold_pct <= 0:
        return 0.0
    t0 = time.monotonic()
    other = other_cpu_pct(pids, 0.3)
    if other < threshold_pct:
        return other
    log(f"  [{label}] waiting for other processes to quiet down (using {other:.0f}% of a core)")
    while time.monotonic() - t0 < max_wait_s:
        other = other_cpu_pct(pids, 0.5)
        if other < threshold_pct:
            log(f"  [{label}] quiet after {time.monotonic() - t0:.0f} s")
            return other
    log(f"  [{label}] still busy after {max_wait_s:.0f} s ({other:.0f}%); measuring anyway")
    return other


INTERFERENCE_PCT = 20.0  # a lossy trial during which others used more than this is repeated
INTERFERENCE_RETRIES = 3


def run_trial_retrying(path: Path, rate: float, duration_s: float, **kw) -> Trial:
    """run_trial, repeated (after waiting for quiet) while it lost packets under interference."""
    for attempt in range(INTERFERENCE_RETRIES + 1):
        wait_idle(path)
        t = run_trial(path, rate, duration_s, **kw)
        if t.clean or t.other_cpu_pct < INTERFERENCE_PCT or path.idle_threshold_pct <= 0:
            return t
        if attempt < INTERFERENCE_RETRIES:
            log(f"  [{path.name}] lost packets while other processes used {t.other_cpu_pct:.0f}% "
                f"of a core; repeating   ({t.line()})")
    return t


def run_trial(path: Path, rate: float, duration_s: float, stamp: bool = False,
              min_sleep_s: float = 0.001) -> Trial:
    path.check_router()
    n = max(1, int(rate * duration_s))
    lo = path.seqs.take(n)
    path.sender.call("prepare", lo, n)
    path.receiver.call("reset", lo, n, stamp)
    pids = path.pids()
    d0 = udp_drops(path.ports.values())
    cpu0 = {k: cpu_seconds(p) for k, p in pids.items()}
    m0 = machine_busy_s()
    w0 = time.monotonic()
    res = path.sender.call("run", lo, n, rate, stamp, min_sleep_s)
    # drain: until everything arrived, or nothing new for 0.5 s (CPU % is over the time until the
    # last packet arrived, so that the idle wait does not dilute it)
    last, last_change = -1, time.monotonic()
    while True:
        got = path.receiver.call("count")
        now = time.monotonic()
        if got >= n:
            last_change = now
            break
        if got != last:
            last, last_change = got, now
        elif now - last_change > 0.5:
            break
        time.sleep(0.02)
    wall = max(last_change - w0, 1e-3)
    cpu1 = {k: cpu_seconds(p) for k, p in pids.items()}
    m1 = machine_busy_s()
    wall_all = time.monotonic() - w0
    d1 = udp_drops(path.ports.values())
    rep = path.receiver.call("report")
    path.check_router()
    return Trial(rate=rate, offered=n, received=rep["uniq"], dup=rep["dup"], reorder=rep["reorder"],
                 stale=rep["stale"], sender_rate=res["rate_achieved"], sender_max_lag_s=res["max_lag_s"],
                 cpu_pct={k: 100.0 * (cpu1[k] - cpu0[k]) / wall for k in pids},
                 other_cpu_pct=max(0.0, 100.0 * ((m1 - m0) - sum(cpu1[k] - cpu0[k] for k in pids)) / wall_all),
                 drops={k: d1[p] - d0[p] for k, p in path.ports.items()}, report=rep,
                 send_stamps=res["stamps"])


def wait_path_ready(path: Path, timeout_s: float = 20.0) -> float:
    """Heartbeats both ways, then probes until packets arrive; returns seconds it took."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        path.check_router()
        path.receiver.call("hb")
        path.sender.call("hb")
        time.sleep(0.1)
        t = run_trial(path, 1000, 0.01, min_sleep_s=0)
        if t.received:
            time.sleep(0.2)
            return time.monotonic() - t0
        time.sleep(0.2)
    raise TimeoutError(f"no packet got through {path.name} in {timeout_s:.0f} s")


@dataclass
class SearchResult:
    rate: float
    sender_limited: bool
    trials: list[Trial]
    best: Trial | None
    confirmed: bool = False

    @property
    def router_cpu_pct(self) -> float | None:
        return self.best.cpu_pct.get("router") if self.best else None


def search_throughput(path: Path, duration_s: float, precision: float, start_rate: float = 2000,
                      max_rate: float = 400_000, confirm: bool = True) -> SearchResult:
    trials: list[Trial] = []
    good: Trial | None = None
    bad_rate: float | None = None
    rate = start_rate
    sender_limited = False

    def step(r: float) -> Trial:
        t = run_trial_retrying(path, round(r, -2), duration_s)
        trials.append(t)
        log(f"  [{path.name}] {'ok  ' if t.clean else 'LOSS'} {t.line()}")
        time.sleep(0.3)
        return t

    while True:
        t = step(rate)
        if t.sender_limited():
            sender_limited = True
            if t.clean:
                good = t
            log(f"  [{path.name}] sender could not keep {t.rate:.0f}/s (reached {t.sender_rate:.0f}/s)")
            break
        if t.clean:
            good = t
            if bad_rate is None:
                if t.rate >= max_rate:
                    break
                rate = min(max_rate, t.rate * 2)
                continue
        else:
            bad_rate = t.rate if bad_rate is None else min(bad_rate, t.rate)
        lo = good.rate if good else 0.0
        if good and (bad_rate - lo) / lo <= precision:
            break
        if not good and bad_rate <= 200:
            break
        rate = (lo + bad_rate) / 2 if good else bad_rate / 2
    confirmed = False
    if confirm and good is not None and not sender_limited:
        rate = good.rate
        for _ in range(10):
            t = run_trial_retrying(path, rate, duration_s * 2)
            trials.append(t)
            log(f"  [{path.name}] confirm {'ok  ' if t.clean else 'LOSS'} {t.line()}")
            time.sleep(0.3)
            if t.clean:
                good, confirmed = t, True
                break
            rate = round(rate * (0.95 if t.lost < 0.01 * t.offered else 0.9), -2)
    return SearchResult(rate=good.rate if good else 0.0, sender_limited=sender_limited, trials=trials,
                        best=good, confirmed=confirmed)


def percentile(sorted_values: list[float], q: float) -> float:
    """Nearest-rank percentile of an already sorted list."""
    if not sorted_values:
        return float("nan")
    k = max(0, min(len(sorted_values) - 1, math.ceil(q / 100.0 * len(sorted_values)) - 1))
    return sorted_values[k]


@dataclass
class LatencyResult:
    rate: float
    samples: int
    lost: int
    p50_ms: float
    p99_ms: float
    max_ms: float
    mean_ms: float
    router_cpu_pct: float | None
    other_cpu_pct: float = 0.0
    # paired baseline: the direct path, measured in blocks alternating with the routed ones
    direct_samples: int = 0
    direct_p50_ms: float | None = None
    direct_p99_ms: float | None = None
    added_p50_ms: float | None = None
    added_p99_ms: float | None = None
    blocks: int = 0
    disturbed_blocks: int = 0  # block pairs thrown away because other processes used > 20 %


def _latencies_ms(t: Trial) -> list[float]:
    recv, send = t.report["stamps"], t.send_stamps
    return [(recv[s] - send[s]) / 1e6 for s in recv if s in send]


def _summary(lat: list[float]) -> tuple[float, float, float, float]:
    lat.sort()
    if not lat:
        return (float("nan"),) * 4
    return percentile(lat, 50), percentile(lat, 99), lat[-1], statistics.fmean(lat)


def measure_latency(path: Path, rate: float, duration_s: float, block_s: float = 1.0) -> LatencyResult:
    """Latency at ``rate``: one-way, sender stamp to receiver stamp.

    For a routed path the direct path (sender straight to the receiver) is measured too, in
    ``block_s`` blocks alternating with the routed ones (direct-routed, then routed-direct, ...),
    so that both see the same machine; "added by routing" is routed minus direct, percentile by
    percentile, over ``duration_s`` of each.  A block pair during which other processes used more
    than 20 % of a core is discarded and measured again (at most 3 x as many pairs in all; if there
    are still not enough clean pairs, the disturbed ones are used too and counted as such).
    """
    if path.router is None:
        return _latency_single(path, rate, duration_s)
    routed_dest = path.sender.call("get_dest")
    direct_dest = ("127.0.0.1", path.receiver.port)
    need = max(1, math.ceil(duration_s / block_s))
    clean: list[dict[str, Trial]] = []
    disturbed: list[dict[str, Trial]] = []
    blocks = 0
    try:
        while len(clean) < need and blocks < 3 * need:
            wait_idle(path)
            pair = {}
            for kind in (("direct", "routed") if blocks % 2 == 0 else ("routed", "direct")):
                path.sender.call("dest", direct_dest if kind == "direct" else routed_dest)
                pair[kind] = run_trial(path, rate, block_s, stamp=True, min_sleep_s=0.0)
            blocks += 1
            if path.idle_threshold_pct > 0 and max(t.other_cpu_pct for t in pair.values()) >= INTERFERENCE_PCT:
                disturbed.append(pair)
            else:
                clean.append(pair)
    finally:
        path.sender.call("dest", routed_dest)
    used = clean + (disturbed[: need - len(clean)] if len(clean) < need else [])
    routed = [x for p in used for x in _latencies_ms(p["routed"])]
    direct = [x for p in used for x in _latencies_ms(p["direct"])]
    p50, p99, mx, mean = _summary(routed)
    d50, d99, _, _ = _summary(direct)
    n_used = max(1, len(used))
    r = LatencyResult(
        rate=rate, samples=len(routed), lost=sum(p["routed"].lost for p in used), p50_ms=p50, p99_ms=p99,
        max_ms=mx, mean_ms=mean,
        router_cpu_pct=sum(p["routed"].cpu_pct.get("router", 0.0) for p in used) / n_used,
        other_cpu_pct=sum(max(t.other_cpu_pct for t in p.values()) for p in used) / n_used,
        direct_samples=len(direct), direct_p50_ms=d50, direct_p99_ms=d99, added_p50_ms=p50 - d50,
        added_p99_ms=p99 - d99, blocks=blocks, disturbed_blocks=len(disturbed))
    log(f"  [{path.name}] latency at {rate:.0f}/s: n={r.samples} lost={r.lost} p50 {p50:.3f} ms p99 {p99:.3f} ms "
        f"max {mx:.3f} ms; direct (paired) p50 {d50:.3f} p99 {d99:.3f} ms; added p50 {r.added_p50_ms:.3f} "
        f"p99 {r.added_p99_ms:.3f} ms; {len(used)} block pairs used, {len(disturbed)} disturbed"
        + (f", OTHER PROCESSES {r.other_cpu_pct:.0f}%" if r.other_cpu_pct >= 5 else ""))
    return r


def _latency_single(path: Path, rate: float, duration_s: float) -> LatencyResult:
    best = None
    for _ in range(INTERFERENCE_RETRIES + 1):  # tail latency is what interference spoils first
        wait_idle(path)
        t = run_trial(path, rate, duration_s, stamp=True, min_sleep_s=0.0)
        if best is None or t.other_cpu_pct < best.other_cpu_pct:
            best = t
        if t.other_cpu_pct < INTERFERENCE_PCT or path.idle_threshold_pct <= 0:
            break
        log(f"  [{path.name}] latency sample disturbed (other processes {t.other_cpu_pct:.0f}%); repeating")
    t = best
    p50, p99, mx, mean = _summary(_latencies_ms(t))
    r = LatencyResult(rate=rate, samples=t.received, lost=t.lost, p50_ms=p50, p99_ms=p99, max_ms=mx, mean_ms=mean,
                      router_cpu_pct=t.cpu_pct.get("router"), other_cpu_pct=t.other_cpu_pct)
    log(f"  [{path.name}] latency at {rate:.0f}/s: n={r.samples} lost={r.lost} p50 {r.p50_ms:.3f} ms "
        f"p99 {r.p99_ms:.3f} ms max {r.max_ms:.3f} ms" + (f" OTHER PROCESSES {r.other_cpu_pct:.0f}%"
                                                        if r.other_cpu_pct >= 5 else ""))
    return r


# ------------------------------------------------------------------ one vehicle: CPU, RSS, start


@dataclass
class VehicleResult:
    start_to_heartbeat_s: list[float]
    port_bound_s: list[float] = field(default_factory=list)  # launch to the UDP port being bound
    cpu_pct: float | None = None
    window_s: float = 0.0
    rss_mb: float | None = None
    hwm_mb: float | None = None
    msgs_per_s: list[float] = field(default_factory=list)
    heartbeats_per_s: list[float] = field(default_factory=list)
    msg_types: list[dict[str, int]] = field(default_factory=list)
    other_cpu_pct: float = 0.0  # everything else on the machine (ground stations included) in the window
    stop: str = ""


class _GroundStation:
    """A pymavlink ground station on its own UDP socket (sysid 255 or 254)."""

    def __init__(self, sysid: int, dest: tuple[str, int]) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.dest = dest
        self.mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=190)
        self.mav.robust_parsing = True
        self.first_hb: float | None = None
        self.counts: dict[str, int] = {}
        self.total = 0

    def send_heartbeat(self) -> None:
        msg = self.mav.heartbeat_encode(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0, 4)
        try:
            self.sock.sendto(msg.pack(self.mav), self.dest)
        except OSError:
            pass

    def receive(self, vehicle_sysid: int) -> None:
        while True:
            try:
                data = self.sock.recv(65536)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                return  # ICMP port unreachable while the daemon is not up yet
            now = time.perf_counter()
            for m in self.mav.parse_buffer(data) or []:
                if m.get_srcSystem() != vehicle_sysid:
                    continue
                t = m.get_type()
                if t == "HEARTBEAT" and self.first_hb is None:
                    self.first_hb = now
                self.counts[t] = self.counts.get(t, 0) + 1
                self.total += 1

    def close(self) -> None:
        self.sock.close()


def _pump(stations: list[_GroundStation], until: float, period_s: float, vehicle_sysid: int,
          proc: Launched, stop_when_all_heard: bool = False, tick=None) -> None:
    next_hb = 0.0
    while True:
        if tick is not None:
            tick()
        now = time.perf_counter()
        if now >= until:
            return
        if not proc.alive():
            raise RuntimeError(f"gcsd exited with code {proc.popen.returncode}:\n{proc.tail()}")
        if stop_when_all_heard and all(s.first_hb is not None for s in stations):
            return
        if now >= next_hb:
            for s in stations:
                s.send_heartbeat()
            next_hb = now + period_s
        select.select([s.sock for s in stations], [], [], max(0.0, min(until, next_hb) - now))
        for s in stations:
            s.receive(vehicle_sysid)


def measure_vehicle(launch, port: int, window_s: float, start_samples: int, settle_s: float = 3.0,
                    idle_threshold_pct: float = 0.0, idle_wait_s: float = 0.0) -> VehicleResult:
    """``launch()`` starts gcsd (one udp-server channel on ``port``); two ground stations attach."""
    dest = ("127.0.0.1", port)
    starts: list[float] = []
    result = VehicleResult(start_to_heartbeat_s=starts)
    for i in range(start_samples):
        wait_idle_pids([os.getpid()], idle_threshold_pct, idle_wait_s, "gcsd")
        stations = [_GroundStation(255, dest), _GroundStation(254, dest)]
        t0 = time.perf_counter()
        proc = launch()
        try:
            # ground stations knock every 10 ms until the daemon answers (a UDP server only talks
            # to clients that have sent to it)
            bound: list[float] = []

            def watch_port() -> None:
                if not bound and udp_port_bound(port):
                    bound.append(time.perf_counter() - t0)

            _pump(stations, t0 + 15.0, 0.01, 1, proc, stop_when_all_heard=True, tick=watch_port)
            if stations[0].first_hb is None:
                raise RuntimeError(f"no HEARTBEAT within 15 s; gcsd log:\n{proc.tail()}")
            starts.append(stations[0].first_hb - t0)
            result.port_bound_s += bound
            log(f"  [gcsd] start to first HEARTBEAT: {starts[-1]:.3f} s (UDP port bound after "
                f"{bound[0] if bound else float('nan'):.3f} s)")
            if i < start_samples - 1:
                result.stop = proc.stop()
                continue
            _pump(stations, time.perf_counter() + settle_s, 1.0, 1, proc)
            for s in stations:
                s.counts.clear()
                s.total = 0
            c0 = cpu_seconds(proc.pid)
            m0 = machine_busy_s()
            w0 = time.perf_counter()
            _pump(stations, w0 + window_s, 1.0, 1, proc)
            c1 = cpu_seconds(proc.pid)
            m1 = machine_busy_s()
            w1 = time.perf_counter()
            result.other_cpu_pct = max(0.0, 100.0 * ((m1 - m0) - (c1 - c0)) / (w1 - w0))
            result.window_s = w1 - w0
            result.cpu_pct = 100.0 * (c1 - c0) / (w1 - w0)
            result.rss_mb = (proc_status_kb(proc.pid, "VmRSS") or 0) / 1024
            result.hwm_mb = (proc_status_kb(proc.pid, "VmHWM") or 0) / 1024
            result.msgs_per_s = [s.total / result.window_s for s in stations]
            result.heartbeats_per_s = [s.counts.get("HEARTBEAT", 0) / result.window_s for s in stations]
            result.msg_types = [dict(sorted(s.counts.items())) for s in stations]
            log(f"  [gcsd] CPU {result.cpu_pct:.2f} % over {result.window_s:.1f} s, RSS {result.rss_mb:.1f} MB, "
                f"msgs/s per GCS {', '.join(f'{x:.1f}' for x in result.msgs_per_s)}")
            result.stop = proc.stop()
        finally:
            if proc.alive():
                proc.stop()
            for s in stations:
                s.close()
    return result
