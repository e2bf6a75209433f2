"""Parameter list download (PARAM_REQUEST_LIST) on loopback: gcsd against MAVSDK's param_server.

SPEC.md: "full parameter list (1 000 parameters) by PARAM_REQUEST_LIST, loopback: <= 0.5 s".

Servers (each its own process, each answering as sysid 1 / compid 1 on a UDP port on 127.0.0.1):

- ``gcsd (built-in)``: ``python -m gcsd run`` with one ``udp-server`` channel and default stream
  rates, i.e. the parameters a user gets (the shared set plus the ten SR0_* of the one channel).
- ``gcsd (1 000)``: the same daemon started by this file (``serve-gcsd``) after wrapping
  ``gcsd.vehicle.node.vehicle_params`` so the vehicle's ParamStore gets filler definitions ``BENCH_0000``...
  (INT8, INT16, INT32, REAL32 in turn) up to at least 1 000. The built-in copter set is
  ArduPilot 4.6's own (1 000 parameters with one channel: params/data/copter.tsv), so today the
  filler adds nothing and both gcsd rows serve the real ArduCopter list; the wrapper stays for a
  configuration with fewer.
- ``MAVSDK param_server (1 000)``: the ``mavsdk`` package (C++ core through ctypes) as an
  AUTOPILOT component on ``udpin://127.0.0.1:PORT``, ``set_protocol(extended=False)``, serving
  the same 1 000 names and default values (``provide_param_int`` for the integer types: MAVSDK
  serves every int as INT32; ``provide_param_float`` for REAL32).

Client (the same for every server, in the bench process): a UDP socket with a 4 MiB receive
buffer. It sends HEARTBEATs (sysid 250 / compid 190) until the server's HEARTBEAT arrives, then per
repetition: PARAM_REQUEST_LIST; the time is from just before that ``send`` to the arrival of the
datagram that completes every index 0..param_count-1. Frames are walked by header
(``bench.frames.walk_frames``), param_count and param_index read from the payload, so the
client's parsing is not the bottleneck; the datagrams are decoded with pymavlink afterwards
(untimed) to check names and types. A lost PARAM_VALUE is re-requested by index (up to 10 at a
time) after 0.2 s without a new one, as MAVProxy does after 1 s; re-requests and the kernel's drop
count on the client socket are reported (normally both 0). Between repetitions a pause of 0.2-0.7 s
(uniform, seeded), so the request lands at a random phase of the server's own schedule (gcsd
sends from one send pass per channel, run at its stream deadlines or when woken). Besides the
total, the time to the first PARAM_VALUE and the streaming cost per value ((last - first) /
(count - 1)) are reported: they separate a fixed start latency from the per-parameter cost, and
extrapolate the built-in set to 1 000 as first + 1 000 x per-value.

Also, if practical, MAVSDK's own ``param`` plugin (``get_all_params``) as the client of both
1 000-parameter servers (``mavsdk-client``, a subprocess): wall time of the call, after the
plugin was created and one warm-up call.

    python -m bench params            # through bench/run.py (the table at the end)
    python bench/params.py            # this measurement alone, with its own table
"""

from __future__ import annotations

import json
import os
import random
import select
import socket
import statistics
import struct
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

if __package__ in (None, ""):  # run as a script: python bench/params.py
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from bench import mavsdk_peer, report
from bench.frames import walk_frames
from bench.peers import _big_buffers
from bench.routers import (
    Launched,
    _launch,
    free_udp_port,
    gcsd_config,
    udp_drops,
    udp_port_bound,
)

TOTAL = 1000
SPEC_TARGET_S = 0.5
VEHICLE = (1, 1)
CLIENT_SYSID, CLIENT_COMPID = 250, 190
MSGID_PARAM_VALUE = mavlink2.MAVLINK_MSG_ID_PARAM_VALUE
MSGID_HEARTBEAT = mavlink2.MAVLINK_MSG_ID_HEARTBEAT
RETRY_QUIET_S = 0.2  # re-request missing indices after this long without a new one
DOWNLOAD_TIMEOUT_S = 10.0
PAUSE_S = (0.2, 0.7)  # uniform, seeded: the request lands at a random phase of the server's schedule
PAUSE_SEED = 1
THIS = Path(__file__).resolve()
REPO = THIS.parent.parent


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------ the definitions

def filler_defs(n: int, start: int = 0):
    """n bench-only definitions, BENCH_0000..., the four types in turn, each with its range."""
    from gcsd.vehicle.params import INT8, INT16, INT32, REAL32, ParamDef

    kinds = [(INT8, 1, 0, 100), (INT16, 1500, 800, 2200), (INT32, 100_000, 0, 1_000_000),
             (REAL32, 0.25, -1e6, 1e6)]
    out = []
    for i in range(start, start + n):
        ptype, default, lo, hi = kinds[i % 4]
        value = default + (i % 50) * (0.5 if ptype == REAL32 else 1)
        out.append(ParamDef(f"BENCH_{i:04d}", ptype, value, lo, hi, "", "bench filler"))
    return out


def bench_defs(total: int = TOTAL):
    """What ``serve-gcsd`` serves with gcsd's default configuration: the copter's set with one
    channel at default stream rates, then filler up to ``total``."""
    from gcsd.config import DEFAULT_STREAM_RATES_HZ
    from gcsd.vehicle.types import VEHICLE_TYPES, vehicle_params

    defs = vehicle_params(VEHICLE_TYPES["copter"], 1, 255, False, [dict(DEFAULT_STREAM_RATES_HZ)], 1.0)
    return defs + filler_defs(max(0, total - len(defs)))


def serve_gcsd(cfg: str, total: int) -> int:
    """gcsd's own CLI, with every vehicle's definitions padded to ``total`` (bench only)."""
    import gcsd.vehicle.node
    from gcsd.daemon.cli import main

    original = gcsd.vehicle.node.vehicle_params

    def padded(*args, **kwargs):
        defs = original(*args, **kwargs)
        return defs + filler_defs(max(0, total - len(defs)))

    gcsd.vehicle.node.vehicle_params = padded
    return main(["run", "-c", cfg])


def serve_mavsdk(port: int, total: int) -> int:
    """MAVSDK's param_server as an autopilot on udpin://127.0.0.1:port, until SIGTERM."""
    from mavsdk.plugins.param_server import ParamServer

    from gcsd.vehicle.params import REAL32

    with mavsdk_peer.node(f"udpin://127.0.0.1:{port}", autopilot=True) as mavsdk:
        server = ParamServer(mavsdk.server_component())
        server.set_protocol(False)
        for d in bench_defs(total):
            if d.ptype == REAL32:
                server.provide_param_float(d.name, float(d.default))
            else:
                server.provide_param_int(d.name, int(d.default))
        return mavsdk_peer.serve_until_sigterm(server)


def mavsdk_client(port: int, reps: int) -> int:
    """MAVSDK's param plugin against the autopilot on port: one warm-up, then ``reps`` timed
    get_all_params; prints one JSON line."""
    from mavsdk.plugins.param import Param

    def body(system, out: dict) -> None:
        param = Param(system)
        param.get_all_params()
        pauses = random.Random(PAUSE_SEED)
        for _ in range(reps):
            time.sleep(pauses.uniform(*PAUSE_S))
            t0 = time.perf_counter()
            everything = param.get_all_params()
            out["times_s"].append(time.perf_counter() - t0)
            out["counts"].append(len(everything.int_params) + len(everything.float_params)
                                 + len(everything.custom_params))
        param.destroy()

    return mavsdk_peer.client_run(port, body, {"times_s": [], "counts": []})


# ---------------------------------------------------------------------------------- the client

@dataclass
class Download:
    seconds: float  # request sent -> every index received
    first_s: float  # request sent -> first PARAM_VALUE
    count: int
    received: int  # PARAM_VALUE frames from the vehicle, duplicates included
    rerequested: int


@dataclass
class ServerResult:
    name: str
    count: int = 0
    downloads: list[Download] = field(default_factory=list)
    client_drops: int = 0
    names: list[str] = field(default_factory=list)
    types: dict[int, int] = field(default_factory=dict)  # MAV_PARAM_TYPE -> how many
    mavsdk_client_s: list[float] = field(default_factory=list)
    mavsdk_client_counts: list[int] = field(default_factory=list)
    error: str | None = None
    stop: str = ""
    note: str = ""

    def times(self) -> list[float]:
        return sorted(d.seconds for d in self.downloads)

    @property
    def median_s(self) -> float | None:
        return statistics.median(self.times()) if self.downloads else None

    @property
    def best_s(self) -> float | None:
        return self.times()[0] if self.downloads else None

    @property
    def worst_s(self) -> float | None:
        return self.times()[-1] if self.downloads else None

    @property
    def first_median_s(self) -> float | None:
        return statistics.median(d.first_s for d in self.downloads) if self.downloads else None

    @property
    def stream_per_param_s(self) -> float | None:
        """Median of (last - first PARAM_VALUE) / (count - 1): the streaming cost of one value."""
        if not self.downloads or self.count < 2:
            return None
        return statistics.median((d.seconds - d.first_s) / (d.count - 1) for d in self.downloads)

    @property
    def mavsdk_median_s(self) -> float | None:
        return statistics.median(self.mavsdk_client_s) if self.mavsdk_client_s else None


class ListClient:
    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        _big_buffers(self.sock)
        self.sock.connect(("127.0.0.1", port))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.mav = mavlink2.MAVLink(None, srcSystem=CLIENT_SYSID, srcComponent=CLIENT_COMPID)
        self.buf = bytearray(65536)
        self.frames: list[bytes] = []  # every datagram of the last download

    def close(self) -> None:
        self.sock.close()

    def send(self, msg) -> None:
        try:
            self.sock.send(msg.pack(self.mav))
        except ConnectionRefusedError:
            pass

    def _recv(self, timeout_s: float):
        """One datagram (a memoryview of the buffer) or None after timeout_s."""
        try:
            n = self.sock.recv_into(self.buf)
            return n
        except BlockingIOError:
            pass
        except ConnectionRefusedError:
            return None
        if not select.select([self.sock], [], [], max(0.0, timeout_s))[0]:
            return None
        try:
            return self.sock.recv_into(self.buf)
        except (BlockingIOError, ConnectionRefusedError):
            return None

    def connect(self, timeout_s: float = 15.0) -> None:
        deadline = time.monotonic() + timeout_s
        hb = mavlink2.MAVLink_heartbeat_message(
            mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
        next_hb = 0.0
        while time.monotonic() < deadline:
            if time.monotonic() >= next_hb:
                self.send(hb)
                next_hb = time.monotonic() + 0.1
            n = self._recv(0.05)
            if n:
                for sysid, msgid, _ in walk_frames(self.buf, n):
                    if sysid == VEHICLE[0] and msgid == MSGID_HEARTBEAT:
                        self.send(hb)
                        return
        raise TimeoutError(f"no HEARTBEAT from sysid {VEHICLE[0]} within {timeout_s} s")

    def drain(self, quiet_s: float) -> None:
        while self._recv(quiet_s):
            pass

    def download(self, timeout_s: float = DOWNLOAD_TIMEOUT_S) -> Download:
        seen = bytearray()
        have = 0
        count = None
        received = rerequested = 0
        self.frames = []
        buf = self.buf
        t0 = time.perf_counter()
        self.send(mavlink2.MAVLink_param_request_list_message(*VEHICLE))
        last_new = first = t0
        while True:
            n = self._recv(RETRY_QUIET_S)
            now = time.perf_counter()
            if now - t0 > timeout_s:
                raise TimeoutError(f"download incomplete after {timeout_s} s: {have} of {count}")
            if not n:
                if count is None:
                    self.send(mavlink2.MAVLink_param_request_list_message(*VEHICLE))
                    rerequested += 1
                else:
                    missing = [i for i in range(count) if not seen[i]][:10]
                    for i in missing:
                        self.send(mavlink2.MAVLink_param_request_read_message(*VEHICLE, b"", i))
                    rerequested += len(missing)
                continue
            self.frames.append(bytes(buf[:n]))
            for sysid, msgid, off in walk_frames(buf, n):
                if msgid != MSGID_PARAM_VALUE or sysid != VEHICLE[0]:
                    continue
                if not received:
                    first = now
                received += 1
                c, i = struct.unpack_from("<HH", buf, off + 4)
                if count is None:
                    count = c
                    seen = bytearray(count)
                if i < count and not seen[i]:
                    seen[i] = 1
                    have += 1
                    last_new = now
            if count is not None and have == count:
                return Download(last_new - t0, first - t0, count, received, rerequested)

    def decode_last(self) -> list:
        """The PARAM_VALUEs of the last download, decoded with pymavlink (untimed)."""
        mav = mavlink2.MAVLink(None)
        mav.robust_parsing = True
        out = []
        for data in self.frames:
            for msg in mav.parse_buffer(data) or []:
                if msg.get_type() == "PARAM_VALUE":
                    out.append(msg)
        return out


def _measure_server(name: str, port: int, reps: int, server: Launched) -> ServerResult:
    res = ServerResult(name)
    client = ListClient(port)
    try:
        client.connect()
        drops0 = udp_drops([client.port])[client.port]
        pauses = random.Random(PAUSE_SEED)
        for rep in range(reps):
            time.sleep(pauses.uniform(*PAUSE_S))
            client.drain(0.0)
            d = client.download()
            res.downloads.append(d)
            if not server.alive():
                raise RuntimeError(f"{name} exited: {server.tail()}")
        res.client_drops = udp_drops([client.port])[client.port] - drops0
        values = client.decode_last()
        by_name = {}
        for m in values:
            pid = m.param_id.decode() if isinstance(m.param_id, bytes) else m.param_id
            by_name[pid.split("\0", 1)[0]] = m.param_type
        res.count = res.downloads[-1].count
        res.names = sorted(by_name)
        for t in by_name.values():
            res.types[t] = res.types.get(t, 0) + 1
        log(f"[{name}] {res.count} parameters: median {res.median_s * 1000:.1f} ms, best "
            f"{res.best_s * 1000:.1f}, worst {res.worst_s * 1000:.1f} over {reps} downloads; "
            f"re-requests {sum(d.rerequested for d in res.downloads)}, duplicates "
            f"{sum(d.received - d.count for d in res.downloads)}, client socket drops {res.client_drops}")
    except (TimeoutError, RuntimeError, OSError) as exc:
        res.error = str(exc)
        log(f"[{name}] FAILED: {exc}")
    finally:
        client.close()
    return res


def _mavsdk_client(res: ServerResult, port: int, reps: int, workdir: Path) -> None:
    argv = [sys.executable, str(THIS), "mavsdk-client", str(port), str(reps)]
    try:
        out = subprocess.run(argv, capture_output=True, text=True, timeout=60 + 10 * reps, cwd=workdir)
    except subprocess.TimeoutExpired:
        log(f"[{res.name}] MAVSDK get_all_params: timed out")
        return
    (workdir / f"mavsdk-client-{port}.log").write_text(out.stdout + out.stderr)
    line = next((ln for ln in out.stdout.splitlines() if ln.startswith("RESULT ")), None)
    if line is None:
        log(f"[{res.name}] MAVSDK get_all_params: no result (exit {out.returncode})")
        return
    data = json.loads(line[7:])
    if data.get("error"):
        log(f"[{res.name}] MAVSDK get_all_params: {data['error']}")
    res.mavsdk_client_s, res.mavsdk_client_counts = data["times_s"], data["counts"]
    if res.mavsdk_client_s:
        log(f"[{res.name}] MAVSDK get_all_params: median {res.mavsdk_median_s * 1000:.1f} ms "
            f"({', '.join(f'{t * 1000:.1f}' for t in res.mavsdk_client_s)}), "
            f"counts {sorted(set(res.mavsdk_client_counts))}")


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


def _run_server(name: str, launch, port: int, ready_pattern: str | None, reps: int, workdir: Path,
                with_mavsdk_client: bool) -> ServerResult:
    server = launch()
    try:
        _wait_ready(server, port, ready_pattern)
        res = _measure_server(name, port, reps, server)
        if with_mavsdk_client and res.error is None:
            _mavsdk_client(res, port, reps, workdir)
    except (TimeoutError, RuntimeError) as exc:
        res = ServerResult(name, error=str(exc))
        log(f"[{name}] FAILED: {exc}")
    finally:
        stop = server.stop()
    res.stop = stop
    log(f"[{name}] {stop}")
    return res


def measure(workdir: Path, reps: int = 10, mavsdk_client: bool = True,
            env: dict | None = None) -> dict[str, ServerResult]:
    """The three servers in turn, one at a time (the machine has 2 cores).

    ``env``: the environment of the gcsd processes (None: this one's), e.g. a PYTHONPATH that
    selects another build of gcsd; the bench package itself is found through REPO.
    """
    results = {}
    env = dict(os.environ if env is None else env)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))

    port = free_udp_port()
    cfg = gcsd_config(workdir, [f'{{name: gcs, type: udp-server, address: "127.0.0.1:{port}"}}'])
    log(f"[params] gcsd, built-in parameters, one channel, default stream rates; {reps} downloads")
    gcsd_argv = [sys.executable, "-m", "gcsd", "run", "-c", str(cfg)]
    results["gcsd_builtin"] = _run_server("gcsd (built-in)", lambda: _launch("gcsd", gcsd_argv, workdir, env),
                                          port, None, reps, workdir, False)

    port = free_udp_port()
    cfg = gcsd_config(workdir, [f'{{name: gcs, type: udp-server, address: "127.0.0.1:{port}"}}'])
    log(f"[params] gcsd, padded to {TOTAL} parameters; {reps} downloads")
    results["gcsd_1000"] = _run_server(
        f"gcsd ({TOTAL})",
        lambda: _launch("gcsd-params", [sys.executable, str(THIS), "serve-gcsd", str(cfg), str(TOTAL)],
                        workdir, env),
        port, None, reps, workdir, mavsdk_client)

    port = free_udp_port()
    log(f"[params] MAVSDK param_server, {TOTAL} parameters; {reps} downloads")
    results["mavsdk_1000"] = _run_server(
        f"MAVSDK param_server ({TOTAL})",
        lambda: _launch("mavsdk-param-server",
                        [sys.executable, str(THIS), "serve-mavsdk", str(port), str(TOTAL)], workdir, env),
        port, "ready", reps, workdir, mavsdk_client)

    g, m = results["gcsd_1000"], results["mavsdk_1000"]
    if g.names and m.names:
        differ = set(g.names) ^ set(m.names)
        m.note = (f"the same {len(m.names)} names as {g.name}" if not differ
                  else f"WARNING: {len(differ)} names not served by both")
        log(f"[params] {m.name}: {m.note}")
    for r in results.values():
        r.names = []  # checked; not worth 1 000 lines of JSON
    return results


# ---------------------------------------------------------------------------------- the table

def rows(results: dict[str, ServerResult]):
    """(metric, gcsd, MAVSDK, better, target, ok) rows, in bench/run.py's table style."""
    b, g, m = (results.get(k) for k in ("gcsd_builtin", "gcsd_1000", "mavsdk_1000"))
    out = []

    def ms(x):
        return None if x is None else x * 1000

    def us(x):
        return None if x is None else x * 1e6

    def spec(v):
        return v <= SPEC_TARGET_S * 1000

    if b is not None and b.median_s is not None:
        out.append((f"param list, gcsd built-in set ({b.count} params), median (ms)", ms(b.median_s),
                    None, None, "", None))
        out.append(("  request to first PARAM_VALUE, median (ms)", ms(b.first_median_s),
                    None, None, "", None))
        out.append(("  streaming, per parameter (us)", us(b.stream_per_param_s), None, None, "", None))
        extrapolated = b.first_median_s + TOTAL * b.stream_per_param_s
        out.append((f"  extrapolated to {TOTAL} params (ms)", ms(extrapolated), None, None, "<= 500", spec))
    g = g if g is not None and g.downloads else None
    m = m if m is not None and m.downloads else None
    if g is None and m is None:
        return out

    def both(attr, scale):
        return (scale(getattr(g, attr)) if g else None), (scale(getattr(m, attr)) if m else None)

    out.append((f"param list, {TOTAL} params, pymavlink client, median (ms)", *both("median_s", ms), "lo",
                "<= 500", spec))
    out.append((f"param list, {TOTAL} params, pymavlink client, worst (ms)", *both("worst_s", ms), "lo",
                "<= 500", spec))
    out.append(("  request to first PARAM_VALUE, median (ms)", *both("first_median_s", ms), "lo", "", None))
    out.append(("  streaming, per parameter (us)", *both("stream_per_param_s", us), "lo", "", None))
    gm, mm = both("mavsdk_median_s", ms)
    if gm is not None or mm is not None:
        out.append((f"param list, {TOTAL} params, MAVSDK get_all_params, median (ms)", gm, mm,
                    "lo", "", None))
    return out


def notes(results: dict[str, ServerResult]) -> list[str]:
    out = []
    tname = {mavlink2.MAV_PARAM_TYPE_INT8: "INT8", mavlink2.MAV_PARAM_TYPE_INT16: "INT16",
             mavlink2.MAV_PARAM_TYPE_INT32: "INT32", mavlink2.MAV_PARAM_TYPE_REAL32: "REAL32"}
    for r in results.values():
        if r.error:
            out.append(f"{r.name}: {r.error}")
            continue
        if not r.downloads:
            continue
        types = ", ".join(f"{tname.get(t, t)} {n}" for t, n in sorted(r.types.items()))
        out.append(f"{r.name}: {len(r.downloads)} downloads of {r.count} ({types}): "
                   f"{', '.join(f'{d.seconds * 1000:.1f}' for d in r.downloads)} ms (first value after "
                   f"{', '.join(f'{d.first_s * 1000:.1f}' for d in r.downloads)} ms); re-requests "
                   f"{sum(d.rerequested for d in r.downloads)}, duplicates "
                   f"{sum(d.received - d.count for d in r.downloads)}, client socket drops {r.client_drops}; "
                   f"{r.stop}" + (f"; {r.note}" if r.note else ""))
        if r.mavsdk_client_s:
            fast = sum(t < SPEC_TARGET_S for t in r.mavsdk_client_s)
            times = ", ".join(f"{t * 1000:.0f}" for t in r.mavsdk_client_s)
            n = len(r.mavsdk_client_s)
            out.append(f"{r.name}: MAVSDK get_all_params {times} ms ({fast} of {n} within "
                       f"{SPEC_TARGET_S * 1000:.0f} ms; the slow ones are MAVSDK re-requesting "
                       f"what it missed of the burst, see its log)")
    return out


def table(results: dict[str, ServerResult]) -> str:
    return report.comparison_table("MAVSDK param_server", rows(results), notes(results))


def main(argv: list[str]) -> int:
    if argv and argv[0] == "serve-gcsd":
        return serve_gcsd(argv[1], int(argv[2]))
    if argv and argv[0] == "serve-mavsdk":
        return serve_mavsdk(int(argv[1]), int(argv[2]))
    if argv and argv[0] == "mavsdk-client":
        return mavsdk_client(int(argv[1]), int(argv[2]))
    import argparse
    import shutil
    import tempfile

    p = argparse.ArgumentParser(prog="python bench/params.py", description=__doc__.split("\n")[0])
    p.add_argument("--reps", type=int, default=10, help="downloads per server (default 10)")
    p.add_argument("--no-mavsdk-client", action="store_true", help="skip MAVSDK get_all_params as a client")
    p.add_argument("--keep", action="store_true", help="keep the temporary directory (configs, logs)")
    a = p.parse_args(argv)
    workdir = Path(tempfile.mkdtemp(prefix="gcsd-bench-params-"))
    try:
        results = measure(workdir, a.reps, not a.no_mavsdk_client)
    finally:
        if a.keep:
            log(f"kept {workdir}")
        else:
            shutil.rmtree(workdir, ignore_errors=True)
    print(table(results))
    return 1 if any(r.error for r in results.values()) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
