"""Swarm capacity: how many simulated copters at default stream rates one gcsd process sustains,
and the CPU of one vehicle.

SPEC.md: "swarm: simulated vehicles at default rates on one core: >= 100"; "CPU of one simulated
vehicle at default rates ... <= 3 % of one core" (the two-ground-station figure is `bench vehicle`).

Method. For each vehicle count N (full run: 1, 50, 100, 150, 200, 250; quick: 1, 100, 250; 250 is
the configuration's limit, `vehicle.count` 1..250), a fresh ``python -m gcsd run`` with
``vehicle: {count: N}`` (type copter), one ``udp-server`` channel on 127.0.0.1 with the default
stream rates (SPEC.md's SRn_ defaults: about 65 messages per second per vehicle), log level warning,
a fresh state directory. gcsd is single-threaded: one process is one core at most. The ground
station is this process: one UDP socket (8 MiB receive buffer) that sends a HEARTBEAT as sysid 255
every second and counts every datagram by the sending sysid and message id, read from the MAVLink
header without decoding. After 3 s of settling (every vehicle heard), a window of W seconds (full
20, quick 5): gcsd's CPU = (utime + stime) over the window (/proc/PID/stat) / W, in % of one core;
messages per second received from each vehicle, and its HEARTBEATs.

N is *sustained* when gcsd used less than 90 % of one core and every vehicle delivered at least
95 % of the messages per second that a lone vehicle delivers (N = 1, same window) and at least
0.9 HEARTBEAT per second, i.e. no vehicle is starved. The result is the largest sustained N, the
CPU of one vehicle (the N = 1 figure) and the marginal CPU per vehicle ((CPU(N) - CPU(1)) / (N - 1)
at the largest N measured), from which 90 % of a core / marginal CPU extrapolates the count one core
would carry beyond the configuration's limit.

    python -m bench swarm          # through bench/run.py
    python bench/swarm.py [--quick]
"""

from __future__ import annotations

import select
import socket
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

if __package__ in (None, ""):  # run as a script: python bench/swarm.py
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench.routers import cpu_seconds, free_udp_port, gcsd_config, start_gcsd

FULL_COUNTS = (1, 50, 100, 150, 200, 250)
QUICK_COUNTS = (1, 100, 250)
SETTLE_S = 3.0
CPU_LIMIT_PCT = 90.0
RATE_FRACTION = 0.95
MIN_HEARTBEAT_HZ = 0.9
SPEC_TARGET = 100


def _heartbeat_frame() -> bytes:
    from pymavlink.dialects.v20 import ardupilotmega as M
    mav = M.MAVLink(None, srcSystem=255, srcComponent=190)
    return bytes(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3).pack(mav))


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


@dataclass
class Trial:
    count: int
    cpu_pct: float
    msgs_per_s_min: float
    msgs_per_s_median: float
    heartbeat_hz_min: float
    heard: int
    sustained: bool = False
    error: str | None = None


@dataclass
class SwarmResult:
    trials: list[Trial] = field(default_factory=list)
    window_s: float = 0.0
    largest_sustained: int | None = None
    one_vehicle_cpu_pct: float | None = None
    marginal_cpu_pct: float | None = None
    extrapolated: float | None = None


def _trial(workdir: Path, count: int, window_s: float, env) -> Trial:
    port = free_udp_port()
    run_dir = workdir / f"swarm-{count}"
    run_dir.mkdir(parents=True, exist_ok=True)
    cfg = gcsd_config(run_dir, [f'{{name: gcs, type: udp-server, address: "127.0.0.1:{port}"}}'],
                      extra=f"vehicle: {{type: copter, count: {count}}}")
    proc = start_gcsd(run_dir, cfg, env=env)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    sock.setblocking(False)
    hb = _heartbeat_frame()
    try:
        counts: dict[int, int] = {}
        beats: dict[int, int] = {}
        started = time.monotonic()
        last_hb = 0.0
        window_start = cpu0 = None
        while True:
            now = time.monotonic()
            if not proc.alive():
                return Trial(count, 0, 0, 0, 0, 0, error=f"gcsd exited: {proc.tail()}")
            if now - last_hb >= (1.0 if window_start is not None else 0.05):
                sock.sendto(hb, ("127.0.0.1", port))
                last_hb = now
            if window_start is None and now - started >= SETTLE_S and len(beats) >= count:
                counts.clear()
                beats.clear()
                window_start, cpu0 = now, cpu_seconds(proc.pid)
            if window_start is not None and now - window_start >= window_s:
                cpu = (cpu_seconds(proc.pid) - cpu0) / (now - window_start) * 100.0
                elapsed = now - window_start
                break
            if window_start is None and now - started > SETTLE_S + 30:
                return Trial(count, 0, 0, 0, 0, len(beats), error=f"only {len(beats)} of {count} vehicles heard")
            ready, _, _ = select.select([sock], [], [], 0.02)
            if not ready:
                continue
            while True:
                try:
                    data = sock.recv(65536)
                except BlockingIOError:
                    break
                if data[0] == 0xFD and len(data) >= 10:
                    sysid, msgid = data[5], data[7] | data[8] << 8 | data[9] << 16
                elif data[0] == 0xFE and len(data) >= 6:
                    sysid, msgid = data[3], data[5]
                else:
                    continue
                counts[sysid] = counts.get(sysid, 0) + 1
                if msgid == 0:
                    beats[sysid] = beats.get(sysid, 0) + 1
        rates = [counts.get(s, 0) / elapsed for s in range(1, count + 1)]
        hbs = [beats.get(s, 0) / elapsed for s in range(1, count + 1)]
        return Trial(count, cpu, min(rates), statistics.median(rates), min(hbs), len(counts))
    finally:
        sock.close()
        proc.stop()


def measure(workdir: Path, quick: bool = False, env=None, counts=None, window_s: float | None = None) -> SwarmResult:
    counts = tuple(counts or (QUICK_COUNTS if quick else FULL_COUNTS))
    window_s = window_s or (5.0 if quick else 20.0)
    res = SwarmResult(window_s=window_s)
    lone = None
    for n in counts:
        log(f"[swarm] {n} copter(s), default rates, {window_s:.0f} s window")
        t = _trial(Path(workdir), n, window_s, env)
        if t.error is None:
            if n == 1:
                lone = t.msgs_per_s_median
                res.one_vehicle_cpu_pct = t.cpu_pct
            reference = lone or t.msgs_per_s_median
            t.sustained = (t.cpu_pct < CPU_LIMIT_PCT and t.msgs_per_s_min >= RATE_FRACTION * reference
                           and t.heartbeat_hz_min >= MIN_HEARTBEAT_HZ)
            if t.sustained:
                res.largest_sustained = max(res.largest_sustained or 0, n)
        log(f"[swarm]   cpu {t.cpu_pct:.1f} %, msgs/s per vehicle min {t.msgs_per_s_min:.1f} median "
            f"{t.msgs_per_s_median:.1f}, heartbeat min {t.heartbeat_hz_min:.2f} Hz, sustained {t.sustained}"
            + (f" ({t.error})" if t.error else ""))
        res.trials.append(t)
    big = max((t for t in res.trials if t.error is None and t.count > 1), key=lambda t: t.count, default=None)
    if big is not None and res.one_vehicle_cpu_pct is not None:
        res.marginal_cpu_pct = (big.cpu_pct - res.one_vehicle_cpu_pct) / (big.count - 1)
        if res.marginal_cpu_pct > 0:
            res.extrapolated = CPU_LIMIT_PCT / res.marginal_cpu_pct
    return res


def table(res: SwarmResult) -> str:
    out = [f"Swarm: copters at default rates in one gcsd process (bench/swarm.py), {res.window_s:.0f} s windows", "",
           "| vehicles | gcsd CPU (% of one core) | msgs/s per vehicle, min | median | HEARTBEAT/s, min | sustained |",
           "|---:|---:|---:|---:|---:|---|"]
    for t in res.trials:
        if t.error:
            out.append(f"| {t.count} | n/a | | | | error: {t.error} |")
            continue
        out.append(f"| {t.count} | {t.cpu_pct:.1f} | {t.msgs_per_s_min:.1f} | {t.msgs_per_s_median:.1f} | "
                   f"{t.heartbeat_hz_min:.2f} | {'yes' if t.sustained else 'NO'} |")
    out.append("")
    meets = res.largest_sustained is not None and res.largest_sustained >= SPEC_TARGET
    out.append(f"largest count sustained: {res.largest_sustained} (SPEC >= {SPEC_TARGET}: {'yes' if meets else 'NO'})")
    if res.one_vehicle_cpu_pct is not None:
        out.append(f"CPU of one vehicle (N = 1, one ground station): {res.one_vehicle_cpu_pct:.2f} % of one core")
    if res.marginal_cpu_pct is not None:
        out.append(f"marginal CPU per vehicle: {res.marginal_cpu_pct:.3f} % of one core; "
                   f"{CPU_LIMIT_PCT:.0f} % of a core would carry about {res.extrapolated:.0f} vehicles")
    return "\n".join(out)


def main(argv=None) -> int:
    import argparse
    import shutil
    import tempfile

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--counts", help="comma list of vehicle counts")
    p.add_argument("--window-s", type=float)
    a = p.parse_args(argv)
    workdir = Path(tempfile.mkdtemp(prefix="gcsd-swarm-"))
    try:
        counts = [int(c) for c in a.counts.split(",")] if a.counts else None
        print(table(measure(workdir, a.quick, counts=counts, window_s=a.window_s)))
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
