"""The daemon under the stateful test: `python -m gcsd run -c FILE` as a subprocess, so an escaped
exception is a process exit and its memory and descriptors are its own (/proc/PID).

Three server channels on 127.0.0.1 port 0 (the real ports are read from `channel_opened`):
`gcs` (UDP) and `tcp` (TCP) follow `signing.require`, `open` (UDP) is `unsigned_ok`, the trusted
link a SETUP_SIGNING may come from unsigned. `stop(sig)` is SIGTERM (a clean stop: exit 0 within
10 s) or SIGKILL (a crash); `start()` again runs on the same state directory.

`status()` is what `gcsd status --json` prints (the control socket's JSON, read the same way);
`state_files()` parses mav.parm, the plans and signing.key as the daemon itself reads them.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import yaml

from gcsd.api import control
from gcsd.vehicle.mission import wpl
from gcsd.vehicle.params.parmfile import read_parm
from gcsd.wire.signing import SigningStore

REPO_SRC = Path(__file__).resolve().parents[2] / "src"
START_TIMEOUT_S = 20.0
STOP_TIMEOUT_S = 10.0
SERVER_CHANNELS = ("gcs", "tcp", "open")
PLANS = ("mission", "fence", "rally")


class Daemon:
    def __init__(self, directory: Path, require: bool, key: bytes | None) -> None:
        self.directory = directory
        self.state_dir = directory / "state"
        self.config_path = directory / "gcsd.yaml"
        self.config = {
            "state_dir": str(self.state_dir),
            "log": {"level": "info", "format": "json"},
            "signing": {"require": require, "key": key.hex() if key else None},
            "channels": [
                {"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"},
                {"name": "tcp", "type": "tcp-server", "address": "127.0.0.1:0"},
                {"name": "open", "type": "udp-server", "address": "127.0.0.1:0", "options": ["unsigned_ok"]},
            ],
        }
        self.config_path.write_text(yaml.safe_dump(self.config, sort_keys=False))
        self.log_path = directory / "gcsd.log"
        self.proc: subprocess.Popen | None = None
        self.ports: dict[str, int] = {}
        self.starts = 0
        self._log_start = 0

    # --- process ---------------------------------------------------------------------------------
    def start(self) -> None:
        self._log_start = self.log_path.stat().st_size if self.log_path.exists() else 0
        pythonpath = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p] + [str(REPO_SRC)]
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(pythonpath), PYTHONUNBUFFERED="1",
                   XDG_RUNTIME_DIR=str(self.directory / "run"))  # its registration stays in this test
        with self.log_path.open("ab") as log:
            self.proc = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(self.config_path)],
                                         stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                         env=env, cwd=self.directory)
        self.starts += 1
        self.ports = {}
        end = time.monotonic() + START_TIMEOUT_S
        while set(self.ports) < set(SERVER_CHANNELS):
            assert self.alive(), f"the daemon exited at start ({self.proc.returncode}):\n{self.log_tail()}"
            assert time.monotonic() < end, f"channels not open in {START_TIMEOUT_S} s:\n{self.log_tail()}"
            time.sleep(0.05)
            for record in self.records():
                if record.get("event") == "channel_opened":
                    self.ports[record["channel"]] = int(str(record["address"]).rsplit(":", 1)[1])

    def stop(self, sig: int = signal.SIGTERM) -> int | None:
        """Stop the process; the exit code (None if SIGTERM had to be followed by SIGKILL)."""
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            return self.proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(STOP_TIMEOUT_S)
            return None

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    # --- what the process holds ------------------------------------------------------------------
    def rss_kb(self) -> int:
        for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
        return 0

    def fds(self) -> int:
        return len(os.listdir(f"/proc/{self.proc.pid}/fd"))

    def status(self) -> dict:
        return control.query(self.state_dir / control.SOCKET_NAME)

    def status_cli(self) -> dict:
        """`gcsd status -c FILE --json`, the command itself."""
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([*os.environ.get("PYTHONPATH", "").split(os.pathsep),
                                                           str(REPO_SRC)]),
                   XDG_RUNTIME_DIR=str(self.directory / "run"))
        out = subprocess.run([sys.executable, "-m", "gcsd", "status", "-c", str(self.config_path), "--json"],
                             check=False, capture_output=True, text=True, env=env, cwd=self.directory, timeout=30)
        assert out.returncode == 0, f"gcsd status exited {out.returncode}: {out.stderr}"
        return json.loads(out.stdout)

    def state_files(self) -> dict:
        """Every state file parsed: {"params": {...}, "mission": [...], ..., "signing": SavedSigning}."""
        found: dict = {}
        parm = self.state_dir / "mav.parm"
        if parm.exists():
            values, problems = read_parm(parm)
            assert not problems, f"mav.parm does not parse: {problems}"
            found["params"] = values
        for plan in PLANS:
            path = self.state_dir / f"{plan}.waypoints"
            if path.exists():
                found[plan] = wpl.loads(path.read_text())
        found["signing"] = SigningStore(self.state_dir / "signing.key").load()
        return found

    # --- log -------------------------------------------------------------------------------------
    def records(self, since_start: bool = True) -> list[dict]:
        with self.log_path.open("rb") as f:
            if since_start:
                f.seek(self._log_start)
            text = f.read().decode(errors="replace")
        out = []
        for line in text.splitlines():
            try:
                record = json.loads(line)
            except ValueError:
                record = {"event": line, "level": "raw"}
            out.append(record if isinstance(record, dict) else {"event": line, "level": "raw"})
        return out

    def log_tail(self, lines: int = 30) -> str:
        return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
