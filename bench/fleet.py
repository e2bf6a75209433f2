"""Fleet on an MQTT broker (SPEC.md "Fleet scale", issue 14): vehicles spread over several
vehicle-side gcsd processes, one Mosquitto, a ground-side gcsd with a UDP server, and a ground
station (this process) on that UDP server.

Method. A trial runs, all on 127.0.0.1: Debian's mosquitto (tests/integration/mosquitto.py: a
generated configuration on a free port); per topic (one MAVLink network: 8-bit sysids, so at most
254 vehicles; this bench uses sysids 1..N <= 250) P vehicle-side processes (`python -m gcsd run`,
N/P copters each, consecutive sysids, one `mqtt` channel role vehicle, plus a `udp-server` channel
"direct" with every stream off, the direct path for the latency comparison) and one ground-side
process (a companion on sysid 251: a `udp-server` channel and an `mqtt` channel role ground, sysids
all, its own streams off on the mqtt channel, as in sitl/fleet/ground.yaml). Log level warning. Two stream profiles:
- fleet: the mqtt channel's streams all 0 and, once every vehicle is heard, the ground station
  broadcasts MAV_CMD_SET_MESSAGE_INTERVAL (target 0/0, so every vehicle takes it, through
  TOPIC/down/all) for SYS_STATUS and GLOBAL_POSITION_INT at 1 Hz: HEARTBEAT, SYS_STATUS and
  GLOBAL_POSITION_INT at 1 Hz each, what a fleet-monitoring ground station asks for.
- default: SPEC.md's default SRn_ rates (about 65 messages per second per copter).
The ground station is one UDP socket per ground side (8 MiB receive buffer) that sends a
HEARTBEAT (sysid 255) each second and counts every datagram by source and message id from the
MAVLink header, and the sequence gaps per source (a lost frame anywhere on the path is a gap:
forwarding is byte-exact, sequence numbers included). After every vehicle is heard and 4 s of
settling, a window of W seconds: each process's CPU ((utime + stime) / W from /proc, % of one
core), each vehicle's HEARTBEAT rate and (fleet profile) its SYS_STATUS and GLOBAL_POSITION_INT
rates, each from the intervals between its first and last arrival in the window, its messages/s,
and the gaps. A fleet is *sustained* when every vehicle's HEARTBEAT rate is 1 Hz +- 10 %, (fleet profile)
its SYS_STATUS and GLOBAL_POSITION_INT rates too, (default profile) its messages/s are at least
95 % of the median of the smallest default trial, no frame was lost, and no process used 90 % of a
core or more.

Latency, after the window with the fleet still running: PROBES round trips per path, alternating,
one at a time: PARAM_REQUEST_READ (index 0) to vehicle k, answered by its PARAM_VALUE; "broker"
goes ground station -> ground-side gcsd -> Mosquitto -> vehicle-side gcsd and back, "direct" goes to
the same vehicle-side process's udp-server. Added latency = broker - direct (p50, p99 of the round
trip; one way is about half).

    python -m bench fleet            # through bench/run.py
    python bench/fleet.py [--quick]
"""

from __future__ import annotations

import argparse
import os
import select
import socket
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

if __package__ in (None, ""):  # run as a script: python bench/fleet.py
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pymavlink.dialects.v20 import ardupilotmega as M
from tests.integration.mosquitto import Mosquitto

from bench.routers import Launched, cpu_seconds, free_udp_port, gcsd_config, machine_busy_s, start_gcsd

GROUND_SYSID = 251
SETTLE_S = 4.0
HEARD_TIMEOUT_S = 60.0
CPU_LIMIT_PCT = 90.0
HB_LOW, HB_HIGH = 0.9, 1.1
RATE_FRACTION = 0.95
PROBES = 100
QUIET_PCT = 25.0
ALL_OFF = "{raw_sens: 0, ext_stat: 0, rc_chan: 0, raw_ctrl: 0, position: 0, extra1: 0, extra2: 0, extra3: 0, adsb: 0}"
FLEET_MESSAGES = (M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def pack(msg, sysid: int = 255, compid: int = 190) -> bytes:
    return bytes(msg.pack(M.MAVLink(None, srcSystem=sysid, srcComponent=compid)))


HEARTBEAT = pack(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))


@dataclass
class Trial:
    profile: str
    vehicles: int
    topics: int
    procs_per_topic: int
    heard: int = 0
    hb_min: float = 0.0
    hb_max: float = 0.0
    type_min: float | None = None  # fleet profile: slowest SYS_STATUS / GLOBAL_POSITION_INT rate of any vehicle
    type_max: float | None = None
    msgs_min: float = 0.0
    msgs_median: float = 0.0
    lost: int = 0
    frames: int = 0
    cpu: dict[str, float] = field(default_factory=dict)  # process -> % of one core
    latency_ms: dict[str, tuple[float, float]] = field(default_factory=dict)  # path -> (p50, p99) round trip
    others_pct: float = 0.0  # CPU used by processes outside the trial during the window, % of one core
    sustained: bool = False
    error: str | None = None

    @property
    def vehicle_cpu_per_vehicle(self) -> float:
        """% of one core per vehicle in the vehicle-side processes (their mean)."""
        side = [v for k, v in self.cpu.items() if k.startswith("vehicles")]
        per_proc = self.vehicles / max(1, len(side))
        return statistics.mean(side) / per_proc if side else 0.0


class Station:
    """The ground station on one ground side: counts frames by source and message id, and gaps."""

    def __init__(self, port: int) -> None:
        self.addr = ("127.0.0.1", port)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        self.sock.setblocking(False)
        self.reset()
        self.last_seq: dict[tuple[int, int], int] = {}
        self.replies: list[tuple[int, int]] = []  # (sysid, msgid) of frames a probe may wait for

    def reset(self) -> None:
        self.counts: dict[tuple[int, int], int] = {}
        self.first: dict[tuple[int, int], float] = {}  # (sysid, msgid) -> first and last arrival
        self.last: dict[tuple[int, int], float] = {}
        self.lost = 0
        self.frames = 0

    def rate_hz(self, sysid: int, msgid: int) -> float:
        """From the intervals between the first and last arrival (a count over the window would be
        off by one period at its edges: 7 HEARTBEATs in a 6 s window is not 1.17 Hz)."""
        key = (sysid, msgid)
        n = self.counts.get(key, 0)
        span = self.last.get(key, 0.0) - self.first.get(key, 0.0)
        return (n - 1) / span if n >= 2 and span > 0 else 0.0

    def fileno(self) -> int:
        return self.sock.fileno()

    def send(self, data: bytes, addr=None) -> None:
        self.sock.sendto(data, addr or self.addr)

    def drain(self) -> None:
        counts, last_seq, first, last_t = self.counts, self.last_seq, self.first, self.last
        now = time.monotonic()
        while True:
            try:
                data = self.sock.recv(65536)
            except BlockingIOError:
                return
            if data[0] == 0xFD and len(data) >= 10:
                seq, sysid, compid, msgid = data[4], data[5], data[6], data[7] | data[8] << 8 | data[9] << 16
            elif data[0] == 0xFE and len(data) >= 6:
                seq, sysid, compid, msgid = data[2], data[3], data[4], data[5]
            else:
                continue
            self.frames += 1
            key = (sysid, msgid)
            counts[key] = counts.get(key, 0) + 1
            first.setdefault(key, now)
            last_t[key] = now
            src = (sysid, compid)
            last = last_seq.get(src)
            if last is not None:
                self.lost += (seq - last - 1) & 0xFF
            last_seq[src] = seq
            if msgid == M.MAVLINK_MSG_ID_PARAM_VALUE:
                self.replies.append((sysid, msgid))

    def close(self) -> None:
        self.sock.close()


def _pump(stations: list[Station], seconds: float) -> None:
    end = time.monotonic() + seconds
    while (left := end - time.monotonic()) > 0:
        ready, _, _ = select.select(stations, [], [], min(left, 0.02))
        for s in ready:
            s.drain()


def _vehicle_config(run_dir: Path, broker: str, topic: str, sysid: int, count: int, streams: str | None) -> tuple[Path, int]:
    direct = free_udp_port()
    mqtt = f'{{name: fleet, type: mqtt, broker: "{broker}", topic: {topic}, role: vehicle'
    mqtt += f", streams: {streams}}}" if streams else "}"
    cfg = gcsd_config(run_dir, [mqtt, (f'{{name: direct, type: udp-server, address: "127.0.0.1:{direct}", '
                                      f"streams: {ALL_OFF}}}")],
                      extra=f"vehicle: {{type: copter, sysid: {sysid}, count: {count}}}")
    return cfg, direct


def _ground_config(run_dir: Path, broker: str, topic: str) -> tuple[Path, int]:
    port = free_udp_port()
    cfg = gcsd_config(run_dir, [f'{{name: gcs, type: udp-server, address: "127.0.0.1:{port}"}}',
                                (f'{{name: fleet, type: mqtt, broker: "{broker}", topic: {topic}, role: ground, '
                                f"streams: {ALL_OFF}}}")],
                      extra=f"vehicle: {{type: companion, sysid: {GROUND_SYSID}}}")
    return cfg, port


def _set_interval(station: Station, msgid: int) -> None:
    station.send(pack(M.MAVLink_command_long_message(0, 0, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msgid, 1e6,
                                                     0, 0, 0, 0, 0)))


def _probe(stations: list[Station], via: Station, addr, sysid: int, timeout_s: float = 1.0) -> float | None:
    for s in stations:
        s.drain()
        s.replies.clear()
    req = pack(M.MAVLink_param_request_read_message(sysid, 1, b"", 0), 254, 190)
    t0 = time.perf_counter()
    via.send(req, addr)
    while (left := t0 + timeout_s - time.perf_counter()) > 0:
        ready, _, _ = select.select(stations, [], [], left)
        for s in ready:
            s.drain()
        if any(r[0] == sysid for r in via.replies):
            return (time.perf_counter() - t0) * 1000.0
    return None


def _percentiles(values: list[float]) -> tuple[float, float]:
    if not values:
        return float("nan"), float("nan")
    v = sorted(values)
    return v[len(v) // 2], v[min(len(v) - 1, int(len(v) * 0.99))]


def trial(workdir: Path, profile: str, per_topic: int, topics: int = 1, procs: int = 2, window_s: float = 15.0,
          env=None) -> Trial:
    t = Trial(profile, per_topic * topics, topics, procs)
    run = Path(workdir) / f"fleet-{profile}-{topics}x{per_topic}"
    broker = Mosquitto(run / "broker").start()
    launched: dict[str, Launched] = {}
    stations: list[Station] = []
    direct: list[tuple[range, int, Station]] = []  # sysids, udp port, the station that probes them
    try:
        for k in range(topics):
            topic = f"gcsd/bench{k}"
            per_proc = per_topic // procs
            for p in range(procs):
                first = 1 + p * per_proc
                d = run / f"vehicles-{k}-{p}"
                d.mkdir(parents=True, exist_ok=True)
                cfg, port = _vehicle_config(d, broker.url, topic, first, per_proc, ALL_OFF if profile == "fleet" else None)
                launched[f"vehicles-{k}-{p}"] = start_gcsd(d, cfg, env=env)
                direct.append((range(first, first + per_proc), port, None))
            d = run / f"ground-{k}"
            d.mkdir(parents=True, exist_ok=True)
            cfg, port = _ground_config(d, broker.url, topic)
            launched[f"ground-{k}"] = start_gcsd(d, cfg, env=env)
            stations.append(Station(port))
        n = per_topic // procs * procs
        wanted = set(range(1, n + 1))
        started = time.monotonic()
        while True:
            for s in stations:
                s.send(HEARTBEAT)
            _pump(stations, 0.5)
            dead = [name for name, proc in launched.items() if not proc.alive()]
            if dead:
                t.error = f"{dead[0]} exited: {launched[dead[0]].tail()}"
                return t
            heard = [wanted <= {sysid for sysid, _ in s.counts} for s in stations]
            if all(heard):
                break
            if time.monotonic() - started > HEARD_TIMEOUT_S:
                t.heard = sum(len(wanted & {sysid for sysid, _ in s.counts}) for s in stations)
                t.error = f"only {t.heard} of {t.vehicles} vehicles heard in {HEARD_TIMEOUT_S:.0f} s"
                return t
        log(f"[fleet]   all {t.vehicles} vehicles heard after {time.monotonic() - started:.1f} s")
        if profile == "fleet":
            for _ in range(2):
                for s in stations:
                    for msgid in FLEET_MESSAGES:
                        _set_interval(s, msgid)
                _pump(stations, 0.5)
        _pump(stations, SETTLE_S)
        pids = {name: proc.pid for name, proc in launched.items()} | {"mosquitto": broker.pid}
        cpu0 = {name: cpu_seconds(pid) for name, pid in pids.items()}
        own0, busy0 = cpu_seconds(os.getpid()), machine_busy_s()
        for s in stations:
            s.drain()
            s.reset()
        w0 = time.monotonic()
        while time.monotonic() - w0 < window_s:
            for s in stations:
                s.send(HEARTBEAT)
            _pump(stations, min(1.0, window_s - (time.monotonic() - w0)))
        elapsed = time.monotonic() - w0
        t.cpu = {name: (cpu_seconds(pid) - cpu0[name]) / elapsed * 100.0 for name, pid in pids.items()}
        own = (cpu_seconds(os.getpid()) - own0) / elapsed * 100.0
        t.others_pct = max(0.0, (machine_busy_s() - busy0) / elapsed * 100.0 - sum(t.cpu.values()) - own)
        _summarise(t, stations, wanted, elapsed)
        by_path: dict[str, list[float]] = {"broker": [], "direct": []}
        for i in range(PROBES):
            sysids, port, _ = direct[i % len(direct)]
            station = stations[(i % len(direct)) // procs]
            sysid = sysids[(i // len(direct)) % len(sysids)]
            for path, addr in (("broker", None), ("direct", ("127.0.0.1", port))):
                rtt = _probe(stations, station, addr, sysid)
                if rtt is not None:
                    by_path[path].append(rtt)
            _pump(stations, 0.01)
        t.latency_ms = {path: _percentiles(v) for path, v in by_path.items()}
        return t
    finally:
        for s in stations:
            s.close()
        for proc in launched.values():
            proc.stop()
        broker.stop()


def _summarise(t: Trial, stations: list[Station], wanted: set[int], elapsed: float) -> None:
    hbs, msgs, types = [], [], []
    for s in stations:
        for sysid in wanted:
            hbs.append(s.rate_hz(sysid, M.MAVLINK_MSG_ID_HEARTBEAT))
            msgs.append(sum(c for (src, _), c in s.counts.items() if src == sysid) / elapsed)
            if t.profile == "fleet":
                types += [s.rate_hz(sysid, m) for m in FLEET_MESSAGES]
    t.heard = sum(1 for m in msgs if m > 0)
    t.hb_min, t.hb_max = min(hbs), max(hbs)
    t.msgs_min, t.msgs_median = min(msgs), statistics.median(msgs)
    if types:
        t.type_min, t.type_max = min(types), max(types)
    t.lost = sum(s.lost for s in stations)
    t.frames = sum(s.frames for s in stations)


def judge(t: Trial, reference_msgs: float | None) -> None:
    if t.error is not None:
        return
    ok = HB_LOW <= t.hb_min and t.hb_max <= HB_HIGH and t.lost == 0 and max(t.cpu.values()) < CPU_LIMIT_PCT
    if t.type_min is not None:
        ok = ok and HB_LOW <= t.type_min and t.type_max <= HB_HIGH
    if reference_msgs is not None:
        ok = ok and t.msgs_min >= RATE_FRACTION * reference_msgs
    t.sustained = ok


def _wait_quiet(threshold_pct: float = QUIET_PCT, max_wait_s: float = 60.0) -> None:
    """Wait (at most max_wait_s) until the machine's other processes use less than threshold_pct of
    a core over 2 s, so that a trial does not start under someone else's burst."""
    end = time.monotonic() + max_wait_s
    while time.monotonic() < end:
        b0, t0 = machine_busy_s(), time.monotonic()
        time.sleep(2.0)
        busy = (machine_busy_s() - b0) / (time.monotonic() - t0) * 100.0
        if busy < threshold_pct:
            return
        log(f"[fleet]   machine busy ({busy:.0f} % of a core), waiting")


@dataclass
class FleetResult:
    window_s: float
    trials: list[Trial] = field(default_factory=list)
    largest: dict[str, int] = field(default_factory=dict)  # profile -> largest sustained fleet


def measure(workdir: Path, quick: bool = False, env=None, window_s: float | None = None) -> FleetResult:
    window_s = window_s or (6.0 if quick else 15.0)
    res = FleetResult(window_s)
    plan = ([("fleet", 100, 1), ("default", 50, 1)] if quick else
            [("fleet", 250, 1), ("fleet", 250, 2)] + [("default", n, 1) for n in (50, 100, 150, 200, 250)])
    reference = None
    for profile, per_topic, topics in plan:
        _wait_quiet()
        if profile == "default" and res.trials and res.trials[-1].profile == "default" and not res.trials[-1].sustained:
            break  # the previous, smaller default fleet already failed
        log(f"[fleet] {profile} profile: {topics} topic(s) x {per_topic} copters over {2 * topics} vehicle-side "
            f"processes, {window_s:.0f} s window")
        t = trial(workdir, profile, per_topic, topics, 2, window_s, env)
        if profile == "default" and reference is None and t.error is None:
            reference = t.msgs_median
        judge(t, reference if profile == "default" else None)
        if t.sustained:
            res.largest[profile] = max(res.largest.get(profile, 0), t.vehicles)
        log(f"[fleet]   heartbeat {t.hb_min:.2f}..{t.hb_max:.2f} Hz, msgs/s per vehicle min {t.msgs_min:.1f} "
            f"median {t.msgs_median:.1f}, lost {t.lost} of {t.frames}, cpu "
            + ", ".join(f"{k} {v:.0f} %" for k, v in t.cpu.items())
            + f", others {t.others_pct:.0f} %, rtt ms {t.latency_ms}, sustained {t.sustained}"
            + (f" ({t.error})" if t.error else ""))
        res.trials.append(t)
    return res


def table(res: FleetResult) -> str:
    out = [(f"Fleet: copters over vehicle-side gcsd processes -> Mosquitto -> ground-side gcsd -> UDP ground station "
           f"(bench/fleet.py), {res.window_s:.0f} s windows"), "",
           ("| profile | topics x vehicles | HEARTBEAT Hz min..max | msgs/s per vehicle min / median | lost | "
           "CPU per vehicle, vehicle side | ground side CPU | mosquitto CPU | RTT p50/p99 broker | direct | "
            "other load | sustained |"),
           "|---|---|---|---|---:|---:|---:|---:|---|---|---:|---|"]
    for t in res.trials:
        if t.error:
            out.append(f"| {t.profile} | {t.topics} x {t.vehicles // t.topics} | {t.error} | | | | | | | | | no |")
            continue
        ground = max(v for k, v in t.cpu.items() if k.startswith("ground"))
        b, d = t.latency_ms.get("broker", (0, 0)), t.latency_ms.get("direct", (0, 0))
        out.append(f"| {t.profile} | {t.topics} x {t.vehicles // t.topics} | {t.hb_min:.2f}..{t.hb_max:.2f} | "
                   f"{t.msgs_min:.1f} / {t.msgs_median:.1f} | {t.lost} | {t.vehicle_cpu_per_vehicle:.3f} % | "
                   f"{ground:.1f} % | {t.cpu.get('mosquitto', 0):.1f} % | {b[0]:.2f} / {b[1]:.2f} ms | "
                   f"{d[0]:.2f} / {d[1]:.2f} ms | {t.others_pct:.0f} % | {'yes' if t.sustained else 'no'} |")
    out += ["", "Largest sustained fleet: " + ", ".join(f"{p}: {n}" for p, n in res.largest.items())]
    return "\n".join(out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--window", type=float, default=None)
    p.add_argument("--workdir", default=None)
    a = p.parse_args(argv)
    import tempfile
    workdir = Path(a.workdir or tempfile.mkdtemp(prefix="gcsd-bench-fleet-"))
    res = measure(workdir, a.quick, window_s=a.window)
    print(table(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
