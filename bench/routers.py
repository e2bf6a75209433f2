"""Launching the routers under test (gcsd, mavlink-router, MAVProxy), free ports, and /proc sampling.

gcsd runs as ``[sys.executable, "-m", "gcsd", "run", "-c", CFG]`` (optionally under cProfile);
mavlink-router (C++, the binary from $GCSD_MAVLINK_ROUTER: bench/README.md) as ``mavlink-routerd -c CONF`` with two
UDP endpoints in server mode, the equivalent of gcsd's two ``udp-server`` channels (each answers
the address it last heard from; a targeted frame goes where its target system was seen), TCP
server off, log level warning; the binary is ``$GCSD_MAVLINK_ROUTER`` or ``mavlink-routerd`` on
PATH, and the bench skips it with a note when there is neither.
MAVProxy as a pure forwarder: ``mavproxy.py --master=udpin:A --out=udpout:B --non-interactive
--no-state --default-modules= --streamrate=-1`` (it forwards master -> every --out and --out ->
master; only the ``link`` module is loaded; it sends its own 1 Hz HEARTBEAT as sysid 255).
Output of each process goes to a log file in the run's temporary directory; ``stop()`` sends SIGTERM,
waits, and reports the exit code (or that it had to be killed).
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

CLK_TCK = os.sysconf("SC_CLK_TCK")

STREAMS_OFF = ("{raw_sens: 0, ext_stat: 0, rc_chan: 0, raw_ctrl: 0, position: 0, "
               "extra1: 0, extra2: 0, extra3: 0, params: 0, adsb: 0}")


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_seconds(pid: int) -> float:
    """utime + stime of a process from /proc/PID/stat, in seconds."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def machine_busy_s() -> float:
    """CPU seconds spent in user, nice and system mode by all processes on all CPUs (/proc/stat)."""
    with open("/proc/stat") as f:
        cols = f.readline().split()
    return (int(cols[1]) + int(cols[2]) + int(cols[3])) / CLK_TCK


def udp_drops(ports) -> dict[int, int]:
    """Kernel drop counters (receive buffer full) of the UDP sockets bound to these local ports."""
    want = set(ports)
    drops = {p: 0 for p in want}
    try:
        with open("/proc/net/udp") as f:
            next(f)
            for line in f:
                cols = line.split()
                port = int(cols[1].rsplit(":", 1)[1], 16)
                if port in want:
                    drops[port] += int(cols[-1])
    except OSError:
        pass
    return drops


def udp_port_bound(port: int) -> bool:
    return port in _udp_ports()


def _udp_ports() -> set[int]:
    ports = set()
    try:
        with open("/proc/net/udp") as f:
            next(f)
            for line in f:
                ports.add(int(line.split()[1].rsplit(":", 1)[1], 16))
    except OSError:
        pass
    return ports


def proc_status_kb(pid: int, key: str) -> int | None:
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


@dataclass
class Launched:
    name: str
    popen: subprocess.Popen
    log_path: Path
    argv: list[str]

    @property
    def pid(self) -> int:
        return self.popen.pid

    def alive(self) -> bool:
        return self.popen.poll() is None

    def tail(self, lines: int = 6) -> str:
        try:
            text = self.log_path.read_text(errors="replace").splitlines()
        except OSError:
            return ""
        return "\n".join(text[-lines:])

    def stop(self, timeout_s: float = 10.0) -> str:
        """SIGTERM, wait; returns a short description of how it ended."""
        if self.popen.poll() is not None:
            return f"had already exited with code {self.popen.returncode}"
        self.popen.send_signal(signal.SIGTERM)
        t0 = time.monotonic()
        try:
            rc = self.popen.wait(timeout_s)
            return f"exited with code {rc} {time.monotonic() - t0:.2f} s after SIGTERM"
        except subprocess.TimeoutExpired:
            self.popen.kill()
            self.popen.wait(5)
            return f"did not exit within {timeout_s:.0f} s of SIGTERM; killed"


def _launch(name: str, argv: list[str], workdir: Path, env: dict | None = None) -> Launched:
    n = len(list(workdir.glob(f"{name}-*.log")))
    log_path = workdir / f"{name}-{n}.log"
    log = open(log_path, "ab")
    popen = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                             cwd=workdir, env=env, start_new_session=True)
    log.close()
    return Launched(name, popen, log_path, argv)


def gcsd_env(src_dir: Path | None) -> dict | None:
    """Environment that makes ``python -m gcsd`` import the package from src_dir (None: as installed)."""
    if src_dir is None:
        return None
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(src_dir), env.get("PYTHONPATH", "")) if p)
    return env


def export_gcsd_rev(repo: Path, rev: str, dest: Path) -> tuple[Path, str]:
    """``git archive REV src`` into dest, with gcsd.wire._speedups built in place when REV has setup.py
    and a compiler is there (as ``pip install -e .`` would); returns (the src directory to import
    from, a description: REV's short commit, the last commit at or before it that changed src/ if
    different, and whether the compiled packet path is in)."""
    commit = subprocess.run(["git", "rev-parse", "--short", rev], cwd=repo, capture_output=True, text=True,
                            check=True).stdout.strip()
    src_commit = subprocess.run(["git", "log", "-1", "--format=%h", commit, "--", "src"], cwd=repo,
                                capture_output=True, text=True, check=True).stdout.strip()
    has_setup = subprocess.run(["git", "cat-file", "-e", f"{commit}:setup.py"], cwd=repo,
                               capture_output=True, check=False).returncode == 0
    dest.mkdir(parents=True, exist_ok=True)
    paths = ["src", "setup.py", "pyproject.toml", "README.md"] if has_setup else ["src"]
    archive = subprocess.run(["git", "archive", "--format=tar", commit, *paths], cwd=repo, capture_output=True,
                             check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(dest)], input=archive, check=True)
    what = commit if src_commit in ("", commit) else f"{commit} (src/ as of {src_commit})"
    if has_setup:
        built = subprocess.run([sys.executable, "setup.py", "-q", "build_ext", "--inplace"], cwd=dest,
                               capture_output=True, check=False)
        compiled = built.returncode == 0 and any((dest / "src" / "gcsd").glob("**/_speedups*.so"))
        what += ", gcsd.wire._speedups compiled" if compiled else ", pure Python (gcsd.wire._speedups not built)"
    return dest / "src", what


def gcsd_available(env: dict | None = None) -> tuple[bool, str]:
    """Is gcsd importable and does ``python -m gcsd --version`` work?"""
    try:
        out = subprocess.run([sys.executable, "-m", "gcsd", "--version"], capture_output=True,
                             text=True, timeout=30, env=env)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return False, str(exc)
    text = (out.stdout + out.stderr).strip()
    if out.returncode != 0:
        return False, text.splitlines()[-1] if text else f"exit code {out.returncode}"
    return True, text


def gcsd_config(workdir: Path, channels: list[str], extra: str = "", http: str | None = "127.0.0.1:0") -> Path:
    """The API is on, as by default, but on a free port (never the default 8088 another gcsd may hold);
    http=None turns it off."""
    cfg = workdir / f"gcsd-{len(list(workdir.glob('gcsd-*.yaml')))}.yaml"
    lines = [
        f"state_dir: {workdir / 'state'}",
        "log: {level: warning, format: json}",
        "http: {address: null}" if http is None else f'http: {{address: "{http}"}}',
        extra,
        "channels:",
        *[f"  - {c}" for c in channels],
        "",
    ]
    cfg.write_text("\n".join(line for line in lines if line is not None))
    return cfg


def start_gcsd(workdir: Path, cfg: Path, profile_out: Path | None = None, env: dict | None = None) -> Launched:
    argv = [sys.executable]
    if profile_out is not None:
        argv += ["-m", "cProfile", "-o", str(profile_out)]
    argv += ["-m", "gcsd", "run", "-c", str(cfg)]
    return _launch("gcsd", argv, workdir, env)


def routing_gcsd_config(workdir: Path, port_a: int, port_b: int) -> Path:
    return gcsd_config(workdir, [
        f'{{name: a, type: udp-server, address: "127.0.0.1:{port_a}", streams: {STREAMS_OFF}}}',
        f'{{name: b, type: udp-server, address: "127.0.0.1:{port_b}", streams: {STREAMS_OFF}}}',
    ], extra="vehicle: {sysid: 1}")


def mavproxy_script() -> str:
    here = Path(sys.executable).parent / "mavproxy.py"
    if here.exists():
        return str(here)
    found = shutil.which("mavproxy.py")
    if not found:
        raise FileNotFoundError("mavproxy.py not found next to the interpreter or on PATH")
    return found


def start_mavproxy(workdir: Path, port_a: int, port_b: int) -> Launched:
    argv = [sys.executable, mavproxy_script(), f"--master=udpin:127.0.0.1:{port_a}",
            f"--out=udpout:127.0.0.1:{port_b}", "--non-interactive", "--no-state",
            "--default-modules=", "--streamrate=-1"]
    return _launch("mavproxy", argv, workdir)


MAVLINK_ROUTER_ENV = "GCSD_MAVLINK_ROUTER"


def mavlink_router_binary() -> tuple[str | None, str]:
    """(path of mavlink-routerd, how it was found) or (None, why not)."""
    path = os.environ.get(MAVLINK_ROUTER_ENV)
    if path:
        if os.access(path, os.X_OK):
            return path, f"${MAVLINK_ROUTER_ENV}={path}"
        return None, f"${MAVLINK_ROUTER_ENV}={path} is not an executable file"
    found = shutil.which("mavlink-routerd")
    if found:
        return found, f"{found} (PATH)"
    return None, f"mavlink-routerd not found: set {MAVLINK_ROUTER_ENV} (mavlink-router built from its public source: bench/README.md)"


def mavlink_router_version(binary: str) -> str:
    try:
        out = subprocess.run([binary, "--version"], capture_output=True, text=True, timeout=10, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return str(exc)
    return (out.stdout + out.stderr).strip().splitlines()[0] if (out.stdout + out.stderr).strip() else "?"


def routing_mavlink_router_config(workdir: Path, port_a: int, port_b: int) -> Path:
    cfg = workdir / f"mavlink-router-{len(list(workdir.glob('mavlink-router-*.conf')))}.conf"
    cfg.write_text("\n".join([
        "[General]", "TcpServerPort = 0", "ReportStats = false", "DebugLogLevel = warning", "",
        "[UdpEndpoint a]", "Mode = Server", "Address = 127.0.0.1", f"Port = {port_a}", "",
        "[UdpEndpoint b]", "Mode = Server", "Address = 127.0.0.1", f"Port = {port_b}", "",
    ]))
    return cfg


def start_mavlink_router(workdir: Path, binary: str, cfg: Path) -> Launched:
    return _launch("mavlink-router", [binary, "-c", str(cfg)], workdir)
