"""Mission upload time against packet loss: gcsd's adaptive re-requests against ArduPilot's fixed 1 s.

What is measured: the wall time from the client's upload command to its "accepted" (MISSION_ACK
ACCEPTED), for ITEMS (30) mission items, through a seeded UDP proxy dropping 0, 5, 10, 20 and 30 %
of the datagrams in each direction (tests/integration/mission_client.LossyProxy), for three
clients, each against two daemons:

- ``adaptive``: gcsd with its default configuration (only the port is set): re-requests timed by
  the uploader's measured round trip (gcsd.vehicle.mission.rtt; ceiling mission.retry_ms = 1000).
- ``fixed 1 s``: ArduPilot's timer. ArduPilot SITL is not available here, so the same gcsd is
  started with its re-request timeout replaced by a constant: ``RttEstimator.timeout_s`` returns
  1.0 s plus the link's backlog (ArduPilot: 1000 ms + stream_slowdown_ms), whatever was measured
  (``FIXED_PATCH`` below, applied in the launcher before gcsd's CLI runs). Everything else is
  gcsd's (including its second copy of the final ACK), so the two columns differ by the timer only.

Clients (each as its users run it; a failed attempt is repeated, as its user would, up to
ATTEMPTS times and within CELL_CAP_S):
- MAVSDK ``mission_raw.upload_mission`` (in this process through the mavsdk package): never
  resends an item; gives up after 5 sends of one item or 5 of its 0.5 s timeouts.
- MAVProxy ``wp load`` (a headless ``mavproxy.py`` process): answers each request; stops once it
  has sent the last item; never resends MISSION_COUNT. Its user repeats the command when no ACK
  is printed 2 s after "Sent all", or when the progress (the item requests reaching MAVProxy,
  which its console shows) has stalled for STALL_S (5 s).
- pymavlink: a minimal ground station (``PymavlinkUploader``): answers every request (also a
  repeated last one); resends MISSION_COUNT every 1 s until a first request comes, and its last
  item when no ACK has come 2 s after it answered the last seq (gcsd acknowledges a repeated
  final item again). No item timer of its own, so the vehicle's timer alone decides.

    python -m bench lossy          # through bench/run.py (the table at the end)
    python bench/lossy.py          # this measurement alone (about 5 minutes; --quick: 0 and 20 %)
"""

from __future__ import annotations

import asyncio
import os
import re
import select
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

if __package__ in (None, ""):  # run as a script: python bench/lossy.py
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pymavlink.dialects.v20 import ardupilotmega as M
from tests.integration.mission_client import LossyProxy

from bench.routers import Launched, _launch, free_udp_port, gcsd_config, gcsd_env, udp_port_bound

ITEMS = 30
LOSSES = (0.0, 0.05, 0.10, 0.20, 0.30)
QUICK_LOSSES = (0.0, 0.20)
ATTEMPTS = 4
STALL_S = 5.0
CELL_CAP_S = 45.0
CLIENTS = ("MAVSDK", "MAVProxy", "pymavlink")
MODES = ("adaptive", "fixed 1 s")
HOME = (-353632620, 1491652370, 584.0)
FIXED_PATCH = (
    "import sys, gcsd.vehicle.mission.rtt as r; "
    "r.RttEstimator.timeout_s = lambda self, queued_s=0.0: 1.0 + max(0.0, queued_s); "  # ArduPilot's fixed 1 s
    "from gcsd.daemon.cli import main; sys.exit(main(sys.argv[1:]))"
)


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def plan(n: int = ITEMS) -> list[tuple]:
    """(seq, frame, command, current, autocontinue, p1..p4, x, y, z, mission_type)."""
    items = [(0, 0, 16, 1, 1, 0.0, 0.0, 0.0, 0.0, HOME[0], HOME[1], HOME[2], 0)]
    return items + [(i, 6, 16, 0, 1, 0.0, 0.0, 0.0, 0.0, HOME[0] + 97 * i, HOME[1] - 53 * i, 10.0 + i, 0)
                    for i in range(1, n)]


@dataclass
class Cell:
    seconds: float | None = None
    attempts: int = 0
    note: str = ""

    def text(self) -> str:
        if self.seconds is None:
            return f"failed ({self.attempts}x{', ' + self.note if self.note else ''})"
        return f"{self.seconds:.2f} s" + (f" ({self.attempts} tries)" if self.attempts > 1 else "")


@dataclass
class Result:
    items: int
    losses: tuple[float, ...]
    cells: dict[str, dict[str, dict[float, Cell]]] = field(default_factory=dict)  # client -> mode -> loss
    error: str | None = None


# ------------------------------------------------------------------------------------- daemons

def start_daemon(workdir: Path, mode: str, env: dict | None) -> tuple[Launched, int]:
    port = free_udp_port()
    cfg = gcsd_config(workdir, [f'{{name: gcs, type: udp-server, address: "127.0.0.1:{port}"}}'])
    if mode == "adaptive":
        argv = [sys.executable, "-m", "gcsd", "run", "-c", str(cfg)]
    else:
        argv = [sys.executable, "-c", FIXED_PATCH, "run", "-c", str(cfg)]
    launched = _launch("gcsd-lossy", argv, workdir, env)
    end = time.monotonic() + 10.0
    while not udp_port_bound(port):
        if not launched.alive() or time.monotonic() > end:
            raise RuntimeError(f"gcsd ({mode}) did not open 127.0.0.1:{port}: {launched.log_path.read_text()[-500:]}")
        time.sleep(0.05)
    return launched, port


def stop(launched: Launched) -> None:
    if launched.alive():
        launched.popen.terminate()
        try:
            launched.popen.wait(5.0)
        except subprocess.TimeoutExpired:
            launched.popen.kill()
            launched.popen.wait(5.0)


# ------------------------------------------------------------------------------------- clients

class WatchedProxy(LossyProxy):
    """The lossy proxy, also noting when a MISSION_REQUEST(_INT) last reached the client."""

    def __init__(self, *args, **kw) -> None:
        self.last_request_s = time.monotonic()
        super().__init__(*args, **kw)

    def _relay(self, way, rng, data, out, to) -> None:
        before = self.forwarded[way]
        super()._relay(way, rng, data, out, to)
        if way == "down" and self.forwarded[way] > before and _msgid(data) in (40, 51):
            self.last_request_s = time.monotonic()


def _msgid(frame: bytes) -> int | None:
    if len(frame) >= 10 and frame[0] == 0xFD:
        return int.from_bytes(frame[7:10], "little")
    if len(frame) >= 6 and frame[0] == 0xFE:
        return frame[5]
    return None


def upload_mavsdk(port: int) -> Cell:
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.mission_raw import MissionItem, MissionRawAsync, MissionRawError

    async def run() -> Cell:
        mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        try:
            await mavsdk.add_any_connection(f"udpout://127.0.0.1:{port}")
            system = await mavsdk.first_autopilot(timeout_s=10.0)
            if system is None:
                return Cell(note="no autopilot")
            mission = MissionRawAsync(system)
            items = [MissionItem(*f) for f in plan()]
            started = time.monotonic()
            try:
                for attempt in range(1, ATTEMPTS + 1):
                    try:
                        await asyncio.wait_for(mission.upload_mission(items), CELL_CAP_S)
                        return Cell(time.monotonic() - started, attempt)
                    except (MissionRawError, TimeoutError):
                        if time.monotonic() - started > CELL_CAP_S:
                            return Cell(None, attempt, "over the cap")
                return Cell(None, ATTEMPTS)
            finally:
                mission.destroy()
        finally:
            mavsdk.destroy()

    return asyncio.run(run())


def upload_mavproxy(port: int, workdir: Path, proxy: WatchedProxy) -> Cell:
    script = shutil.which("mavproxy.py", path=str(Path(sys.executable).parent)) or shutil.which("mavproxy.py")
    if script is None:
        return Cell(note="mavproxy.py not installed")
    home = workdir / "mavproxy-home"
    home.mkdir(exist_ok=True)
    source = workdir / "plan.txt"
    rows = ["QGC WPL 110"] + [
        f"{s}\t{c}\t{fr}\t{cmd}\t{p1}\t{p2}\t{p3}\t{p4}\t{x / 1e7:.7f}\t{y / 1e7:.7f}\t{z:.3f}\t{ac}"
        for s, fr, cmd, c, ac, p1, p2, p3, p4, x, y, z, _ in plan()]
    source.write_text("\n".join(rows) + "\n")
    proc = subprocess.Popen([sys.executable, script, f"--master=udpout:127.0.0.1:{port}", "--no-state",
                             "--default-modules=wp"], cwd=home, env={**os.environ, "HOME": str(home)},
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    lines: list[str] = []

    def wait_for(pattern: str, timeout_s: float, since: int) -> str | None:
        end = time.monotonic() + timeout_s
        index = since
        while True:
            while index < len(lines):
                if re.search(pattern, lines[index]):
                    return lines[index]
                index += 1
            left = end - time.monotonic()
            if left <= 0:
                return None
            if select.select([proc.stdout], [], [], min(left, 0.2))[0]:
                line = proc.stdout.readline()
                if not line:
                    return None
                lines.append(line)

    try:
        if wait_for(r"Detected vehicle 1:1", 20.0, 0) is None:
            return Cell(note="MAVProxy saw no vehicle")
        accepted = r"Got MISSION_ACK: TYPE_MISSION: ACCEPTED"
        started = time.monotonic()
        for attempt in range(1, ATTEMPTS + 1):
            since = len(lines)
            proc.stdin.write(f"wp load {source}\n")
            proc.stdin.flush()
            proxy.last_request_s = time.monotonic()
            found = None
            while found is None and time.monotonic() - proxy.last_request_s < STALL_S:
                found = wait_for(f"(?:{accepted})|(?:Sent all {ITEMS} )", 0.5, since)
            if found is not None and not re.search(accepted, found):
                found = wait_for(accepted, 2.0, since)
            if found is not None:
                return Cell(time.monotonic() - started, attempt)
            if time.monotonic() - started > CELL_CAP_S:
                return Cell(None, attempt, "over the cap")
        return Cell(None, ATTEMPTS)
    finally:
        proc.stdin.close()
        try:
            proc.wait(3.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(3.0)


class PymavlinkUploader:
    """A minimal ground station on pymavlink: answers every MISSION_REQUEST(_INT) with the item;
    resends MISSION_COUNT until the first request, the last item when its ACK is 2 s late."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.to = ("127.0.0.1", port)
        self.mav = M.MAVLink(None, srcSystem=255, srcComponent=190)
        self.mav.robust_parsing = True

    def send(self, msg) -> None:
        self.sock.sendto(msg.pack(self.mav), self.to)

    def upload(self, items: list[tuple], cap_s: float) -> bool:
        self.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
        count = M.MAVLink_mission_count_message(1, 1, len(items), 0)
        self.send(count)
        last_sent, started = count, time.monotonic()
        sent_s, requested = started, False
        while time.monotonic() < started + cap_s:
            if not select.select([self.sock], [], [], 0.05)[0]:
                waited = time.monotonic() - sent_s
                if (not requested and waited > 1.0) or (last_sent is not count and last_sent.seq == len(items) - 1
                                                        and waited > 2.0):
                    self.send(last_sent)  # the count was lost, or the final ACK
                    sent_s = time.monotonic()
                continue
            for msg in self.mav.parse_buffer(self.sock.recv(65536)) or []:
                kind = msg.get_type()
                if kind == "MISSION_ACK" and msg.target_system == 255:
                    return msg.type == M.MAV_MISSION_ACCEPTED
                if kind in ("MISSION_REQUEST", "MISSION_REQUEST_INT") and msg.target_system == 255:
                    requested = True
                    s, fr, cmd, cur, ac, p1, p2, p3, p4, x, y, z, t = items[msg.seq]
                    last_sent = M.MAVLink_mission_item_int_message(1, 1, s, fr, cmd, cur, ac, p1, p2, p3, p4, x, y, z, t)
                    self.send(last_sent)
                    sent_s = time.monotonic()
        return False

    def close(self) -> None:
        self.sock.close()


def upload_pymavlink(port: int) -> Cell:
    """Upload again after a refused or cancelled upload (gcsd's 8 s without an item), as an
    application would, up to ATTEMPTS times within CELL_CAP_S."""
    client = PymavlinkUploader(port)
    try:
        started = time.monotonic()
        for attempt in range(1, ATTEMPTS + 1):
            left = CELL_CAP_S - (time.monotonic() - started)
            if left <= 0:
                return Cell(None, attempt - 1, "over the cap")
            if client.upload(plan(), left):
                return Cell(time.monotonic() - started, attempt)
        return Cell(None, ATTEMPTS)
    finally:
        client.close()


# ----------------------------------------------------------------------------------- measuring

def measure(workdir: Path | None = None, quick: bool = False, env: dict | None = None) -> Result:
    own = workdir is None
    workdir = Path(tempfile.mkdtemp(prefix="gcsd-lossy-")) if own else workdir / "lossy"
    workdir.mkdir(parents=True, exist_ok=True)
    losses = QUICK_LOSSES if quick else LOSSES
    result = Result(ITEMS, losses)
    try:
        for mode in MODES:
            for loss in losses:
                for client in CLIENTS:
                    daemon, port = start_daemon(workdir, mode, env)  # a fresh daemon: no estimate carried over
                    proxy = WatchedProxy(port, loss=loss, seed=int(loss * 1000) + 17)
                    try:
                        if client == "MAVSDK":
                            cell = upload_mavsdk(proxy.port)
                        elif client == "MAVProxy":
                            cell = upload_mavproxy(proxy.port, workdir, proxy)
                        else:
                            cell = upload_pymavlink(proxy.port)
                    except Exception as exc:  # a client that cannot run is a note, not a crash
                        cell = Cell(note=f"{type(exc).__name__}: {exc}")
                    finally:
                        proxy.close()
                        stop(daemon)
                    result.cells.setdefault(client, {}).setdefault(mode, {})[loss] = cell
                    log(f"[lossy] {client:9s} {mode:9s} loss {loss:4.0%}: {cell.text()}")
    except Exception as exc:
        result.error = f"{type(exc).__name__}: {exc}"
        log(f"[lossy] {result.error}")
    finally:
        if own:
            shutil.rmtree(workdir, ignore_errors=True)
    return result


def table(result: Result) -> str:
    losses = result.losses
    head = ["client", "re-request timer", *[f"{loss:.0%} loss" for loss in losses]]
    out = [f"Mission upload of {result.items} items through loss in each direction (bench/lossy.py)", "",
           "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for client in CLIENTS:
        for mode in MODES:
            cells = result.cells.get(client, {}).get(mode, {})
            label = "gcsd adaptive (default)" if mode == "adaptive" else "fixed 1 s (ArduPilot's)"
            out.append(f"| {client} | {label} | " + " | ".join(
                cells[loss].text() if loss in cells else "n/a" for loss in losses) + " |")
    if result.error:
        out += ["", f"error: {result.error}"]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    import argparse

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="0 and 20 %% loss only")
    a = p.parse_args(argv)
    print(table(measure(quick=a.quick, env=gcsd_env(Path(__file__).resolve().parent.parent / "src"))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
