"""PARAM_SET flood: does a client that sets 1 000 parameters a second slow everyone else down?

SPEC.md (Parameters) and issue 11: persistence must not stall the event loop; target: a second
client's PARAM_REQUEST_READ round trip stays under 20 ms at p99 while another client sends
1 000 PARAM_SET/s with changing values.

Setup: ``python -m gcsd run`` (the working tree, or ``--gcsd-rev``'s export) with the default
configuration except one ``udp-server`` channel on a free port on 127.0.0.1 and a temporary
``state_dir``: default stream rates, default persistence (``mav.parm`` in the state directory).

- **Flooder** (its own process, ``python bench/param_flood.py flood``): sysid 251 / compid 190.
  HEARTBEAT until the vehicle answers, then PARAM_SET at 1 000/s for the flood window (sends
  whatever is due, then sleeps until the next is due but at least 1 ms; frames pre-encoded), the
  values changing every time, cycling over four REAL32 parameters (COMPASS_OFS_X/Y/Z and
  BATT_ARM_VOLT; values within their ranges), so every set is a change that must be persisted.
  It reads and counts what comes back (the vehicle confirms each change with PARAM_VALUE on every
  channel) and reports, as JSON, what it sent, the confirmations, and the last value of each name.
- **Prober** (the bench process): sysid 250 / compid 190, HEARTBEAT at 1 Hz. One
  PARAM_REQUEST_READ by index at a time, cycling over indices 0..39 (any the flood touches are
  skipped); the latency is from just before ``sendto`` to the arrival of the PARAM_VALUE with that
  index and a name the flood does not set
  (pymavlink decodes the datagrams; telemetry and the flood's confirmations arrive on the same
  socket and are skipped). A request unanswered after 1 s is counted lost and the next one is
  sent. 10 ms pause between round trips (about 60-90 requests per second).
- Phases: 4 s of probes with no flood (the baseline), then the flood window (10 s; quick 4 s)
  with the probes running throughout, then SIGTERM. After the daemon has exited, ``mav.parm`` is
  read: each flooded parameter must hold the last value sent (a clean stop flushes everything).

Reported: the prober's p50 / p99 / max latency and lost requests, before and during the flood;
the flood's achieved rate and confirmations; the daemon's CPU during the flood; whether the file
held the last values.

    python -m bench param_flood             # through bench/run.py
    python bench/param_flood.py [--quick]   # alone, with its own table
"""

from __future__ import annotations

import json
import os
import select
import socket
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

if __package__ in (None, ""):  # run as a script: python bench/param_flood.py
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from bench.routers import (
    _launch,
    cpu_seconds,
    free_udp_port,
    gcsd_config,
    start_gcsd,
)

RATE = 1000
TARGET_P99_MS = 20.0
VEHICLE = (1, 1)
PROBER = (250, 190)
FLOODER = (251, 190)
FLOODED = {"COMPASS_OFS_X": (-400.0, 400.0), "COMPASS_OFS_Y": (-400.0, 400.0),
           "COMPASS_OFS_Z": (-400.0, 400.0), "BATT_ARM_VOLT": (0.0, 20.0)}
PROBED = range(40)  # parameter indices read by the prober (flooded ones skipped)
REQUEST_TIMEOUT_S = 1.0
PAUSE_S = 0.01


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def _socket(port: int) -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    sock.bind(("127.0.0.1", 0))
    sock.connect(("127.0.0.1", port))
    sock.setblocking(False)
    return sock


def _drain(sock: socket.socket, mav) -> list:
    out = []
    while True:
        try:
            data = sock.recv(65536)
        except (BlockingIOError, InterruptedError, ConnectionRefusedError):
            return out
        out += [m for m in (mav.parse_buffer(data) or []) if m.get_type() != "BAD_DATA"]


def _heartbeat(mav) -> bytes:
    return bytes(mavlink2.MAVLink_heartbeat_message(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID,
                                                    0, 0, 0, 3).pack(mav))


def _attach(sock: socket.socket, mav, timeout_s: float = 15.0) -> None:
    """HEARTBEAT every 50 ms until the vehicle's HEARTBEAT arrives (a udp-server serves a source
    only after a good frame from it)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        sock.send(_heartbeat(mav))
        select.select([sock], [], [], 0.05)
        if any(m.get_type() == "HEARTBEAT" and (m.get_srcSystem(), m.get_srcComponent()) == VEHICLE
               for m in _drain(sock, mav)):
            return
    raise TimeoutError("no HEARTBEAT from the vehicle")


# --- the flooder (a subprocess) --------------------------------------------------------------

def flood(port: int, rate: int, seconds: float) -> dict:
    sock = _socket(port)
    mav = mavlink2.MAVLink(None, srcSystem=FLOODER[0], srcComponent=FLOODER[1])
    mav.robust_parsing = True
    _attach(sock, mav)
    names = list(FLOODED)
    frames, last = [], {}
    for i in range(int(rate * seconds)):
        name = names[i % len(names)]
        lo, hi = FLOODED[name]
        value = lo + (hi - lo) * ((i * 7919) % 10007) / 10007  # a different value every time
        msg = mavlink2.MAVLink_param_set_message(*VEHICLE, name.encode(), value, mavlink2.MAV_PARAM_TYPE_REAL32)
        frames.append(bytes(msg.pack(mav)))
        last[name] = msg.param_value  # as packed: a float32
    confirmed = 0
    start = time.monotonic()
    sent = 0
    next_hb = start + 1.0
    while sent < len(frames):
        now = time.monotonic()
        due = min(len(frames), int((now - start) * rate) + 1)
        while sent < due:
            sock.send(frames[sent])
            sent += 1
        if now >= next_hb:
            sock.send(_heartbeat(mav))
            next_hb += 1.0
        confirmed += sum(1 for m in _drain(sock, mav) if m.get_type() == "PARAM_VALUE"
                         and m.param_id in FLOODED)
        time.sleep(max(0.001, start + (sent + 1) / rate - time.monotonic()))
    elapsed = time.monotonic() - start
    settle = time.monotonic() + 1.0
    while time.monotonic() < settle:
        select.select([sock], [], [], 0.05)
        confirmed += sum(1 for m in _drain(sock, mav) if m.get_type() == "PARAM_VALUE"
                         and m.param_id in FLOODED)
    sock.close()
    return {"sent": sent, "elapsed_s": elapsed, "confirmed": confirmed, "last": last}


# --- the prober (the bench process) ----------------------------------------------------------

@dataclass
class Probes:
    latencies_ms: list[float] = field(default_factory=list)
    lost: int = 0

    def pct(self, p: float) -> float | None:
        xs = sorted(self.latencies_ms)
        return xs[min(len(xs) - 1, max(0, round(p / 100 * len(xs) + 0.5) - 1))] if xs else None


class Prober:
    def __init__(self, port: int) -> None:
        self.sock = _socket(port)
        self.mav = mavlink2.MAVLink(None, srcSystem=PROBER[0], srcComponent=PROBER[1])
        self.mav.robust_parsing = True
        self.i = 0
        self.next_hb = 0.0
        self.names: dict[int, str] = {}  # index -> name, learnt from the replies

    def attach(self) -> None:
        _attach(self.sock, self.mav)

    def run(self, seconds: float, until=None) -> Probes:
        """Round trips for `seconds`, or until until() is true."""
        out = Probes()
        end = time.monotonic() + seconds
        while time.monotonic() < end and not (until is not None and until()):
            index = PROBED[self.i % len(PROBED)]
            self.i += 1
            if self.names.get(index) in FLOODED:
                continue
            raw = bytes(mavlink2.MAVLink_param_request_read_message(*VEHICLE, b"", index).pack(self.mav))
            t0 = time.perf_counter()
            self.sock.send(raw)
            got = False
            while not got and time.perf_counter() - t0 < REQUEST_TIMEOUT_S:
                select.select([self.sock], [], [], 0.05)
                now = time.perf_counter()
                for m in _drain(self.sock, self.mav):
                    if m.get_type() == "PARAM_VALUE" and m.param_index == index:
                        self.names[index] = m.param_id  # a flooded name is skipped from now on
                        got = True
                if got:
                    out.latencies_ms.append((now - t0) * 1000)
            if not got:
                out.lost += 1
            if time.monotonic() >= self.next_hb:
                self.sock.send(_heartbeat(self.mav))
                self.next_hb = time.monotonic() + 1.0
            time.sleep(PAUSE_S)
        return out

    def close(self) -> None:
        self.sock.close()


@dataclass
class FloodResult:
    baseline: Probes
    during: Probes
    flood: dict
    gcsd_cpu_pct: float
    file_ok: bool
    file_note: str
    stop: str


def _read_parm(path: Path) -> dict[str, float]:
    values = {}
    for line in path.read_text().splitlines():
        parts = line.replace(",", " ").split()
        if len(parts) >= 2 and not line.startswith("#"):
            try:
                values[parts[0]] = float(parts[1])
            except ValueError:
                pass
    return values


def measure(workdir: Path, quick: bool = False, env: dict | None = None) -> FloodResult:
    flood_s = 4.0 if quick else 10.0
    port = free_udp_port()
    wd = workdir / "param-flood"
    wd.mkdir(parents=True, exist_ok=True)
    cfg = gcsd_config(wd, [f'{{name: gcs, type: udp-server, address: "127.0.0.1:{port}"}}'])
    gcsd = start_gcsd(wd, cfg, None, env)
    prober = Prober(port)
    try:
        prober.attach()
        log(f"[param_flood] gcsd pid {gcsd.pid} on 127.0.0.1:{port}; baseline 4 s of PARAM_REQUEST_READ")
        baseline = prober.run(4.0)
        argv = [sys.executable, str(Path(__file__).resolve()), "flood", "--port", str(port),
                "--rate", str(RATE), "--seconds", str(flood_s)]
        flooder = _launch("flooder", argv, wd)
        cpu0, t0 = cpu_seconds(gcsd.pid), time.monotonic()
        log(f"[param_flood] flooder pid {flooder.pid}: {RATE} PARAM_SET/s for {flood_s:.0f} s")
        during = prober.run(flood_s + 20.0, until=lambda: flooder.popen.poll() is not None)
        cpu_pct = (cpu_seconds(gcsd.pid) - cpu0) / (time.monotonic() - t0) * 100
        flooder.popen.wait(30)
        lines = flooder.log_path.read_text().strip().splitlines()
        report = json.loads(lines[-1]) if lines and lines[-1].startswith("{") else {"error": flooder.tail()}
    finally:
        prober.close()
        stop = gcsd.stop()
    parm = wd / "state" / "mav.parm"
    file_ok, note = False, "no mav.parm"
    if parm.exists() and "last" in report:
        saved = _read_parm(parm)
        wrong = {n: (saved.get(n), v) for n, v in report["last"].items()
                 if saved.get(n) is None or abs(saved[n] - v) > 1e-4 * max(1.0, abs(v))}
        file_ok = not wrong
        note = "every flooded parameter holds its last value" if file_ok else f"differs: {wrong}"
    log(f"[param_flood] gcsd {stop}; mav.parm: {note}")
    return FloodResult(baseline, during, report, cpu_pct, file_ok, note, stop)


def table(r: FloodResult) -> str:
    def f(v):
        return "n/a" if v is None else f"{v:.2f}"

    def row(name, p: Probes):
        n = len(p.latencies_ms) + p.lost
        return (f"{name:<34} {n:>6} {f(p.pct(50)):>8} {f(p.pct(99)):>8} "
                f"{f(max(p.latencies_ms) if p.latencies_ms else None):>8} {p.lost:>5}")

    fl = r.flood
    rate = fl.get("sent", 0) / fl["elapsed_s"] if fl.get("elapsed_s") else 0
    meets = r.during.pct(99) is not None and r.during.pct(99) < TARGET_P99_MS and r.during.lost == 0
    return "\n".join([
        (f"PARAM_SET flood: second client's PARAM_REQUEST_READ round trip (ms); SPEC/issue 11: p99 < "
         f"{TARGET_P99_MS:.0f} ms, none lost"),
        "",
        f"{'':<34} {'reqs':>6} {'p50':>8} {'p99':>8} {'max':>8} {'lost':>5}",
        row("before the flood", r.baseline),
        row(f"during {RATE} PARAM_SET/s", r.during),
        "",
        (f"flood: {fl.get('sent', 0)} PARAM_SET in {fl.get('elapsed_s', 0):.2f} s ({rate:,.0f}/s), "
         f"{fl.get('confirmed', 0)} PARAM_VALUE confirmations back to the flooder; gcsd CPU during the flood "
         f"{r.gcsd_cpu_pct:.0f} % of one core; mav.parm after SIGTERM: {r.file_note}; gcsd {r.stop}"),
        f"meets the target: {'yes' if meets else 'NO'}",
    ])


def main(argv: list[str]) -> int:
    import argparse
    import tempfile

    p = argparse.ArgumentParser(prog="bench/param_flood.py")
    p.add_argument("mode", nargs="?", default="measure", choices=["measure", "flood"])
    p.add_argument("--port", type=int)
    p.add_argument("--rate", type=int, default=RATE)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--quick", action="store_true")
    a = p.parse_args(argv)
    if a.mode == "flood":
        print(json.dumps(flood(a.port, a.rate, a.seconds)), flush=True)
        return 0
    with tempfile.TemporaryDirectory(prefix="gcsd-flood-") as d:
        print(table(measure(Path(d), a.quick, os.environ.copy())))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
