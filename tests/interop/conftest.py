"""Fixtures for interop tests: the real gcsd daemon as a subprocess, and real third-party clients.

`spawn(argv, ...)` starts any program in its own session with stdout and stderr captured line by
line (with the monotonic time each line arrived), so a test can wait for a line and measure when
it came. Every process it started is stopped at teardown: SIGTERM (or the program's own quit
command), a bounded wait, then SIGKILL to the whole process group, so nothing is left behind.

`gcsd_daemon(config_overrides=None)` writes a YAML configuration under `tmp_path` (state in
`tmp_path`, JSON logs, one UDP server channel `gcs` on 127.0.0.1 port 0), runs
`python -m gcsd run -c CONFIG`, reads the real port of every server channel from its
`channel_opened` log events and returns a `GcsdDaemon` with `.port(channel_name)`. At teardown the
daemon gets SIGTERM and must exit with status 0 within 5 s (the SPEC's clean stop).
"""

from __future__ import annotations

import copy
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

REPO_ROOT = Path(__file__).resolve().parents[2]

GCSD_START_TIMEOUT_S = 10.0
GCSD_STOP_TIMEOUT_S = 5.0
PROCESS_KILL_WAIT_S = 5.0



@dataclass(frozen=True)
class HomePosition:
    lat_deg: float
    lon_deg: float
    alt_m: float  # above mean sea level


# The simulated copter's home, from the SPEC's default configuration.
DEFAULT_HOME = HomePosition(lat_deg=-35.363262, lon_deg=149.165237, alt_m=584.0)


class ProcessOutput:
    """Lines a child process wrote, each with the `time.monotonic()` at which it was read."""

    def __init__(self) -> None:
        self._lines: list[tuple[float, str]] = []
        self._changed = threading.Condition()
        self.closed = False

    def append(self, line: str) -> None:
        with self._changed:
            self._lines.append((time.monotonic(), line))
            self._changed.notify_all()

    def close(self) -> None:
        with self._changed:
            self.closed = True
            self._changed.notify_all()

    def __len__(self) -> int:
        with self._changed:
            return len(self._lines)

    def lines(self, since: int = 0) -> list[tuple[float, str]]:
        with self._changed:
            return list(self._lines[since:])

    def text(self) -> str:
        return "\n".join(line for _, line in self.lines())

    def wait_for(
        self, pattern: str | re.Pattern, timeout_s: float, since: int = 0
    ) -> tuple[int, float, re.Match] | None:
        """First line at index >= `since` where `pattern` matches (re.search).

        Returns (index, arrival time, match), or None if no such line arrives within `timeout_s`
        or the process closed its output first.
        """
        regex = re.compile(pattern)
        deadline = time.monotonic() + timeout_s
        index = since
        with self._changed:
            while True:
                while index < len(self._lines):
                    arrived, line = self._lines[index]
                    match = regex.search(line)
                    if match:
                        return index, arrived, match
                    index += 1
                remaining = deadline - time.monotonic()
                if remaining <= 0 or self.closed:
                    return None
                self._changed.wait(remaining)


class SpawnedProcess:
    """A child process in its own session, its output read by a thread into `output`."""

    def __init__(self, name: str, argv: list[str], cwd: Path, env: dict[str, str]) -> None:
        self.name = name
        self.argv = argv
        self.output = ProcessOutput()
        self.started_at = time.monotonic()
        self.popen = subprocess.Popen(
            argv,
            cwd=cwd,
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        self._reader = threading.Thread(target=self._read, name=f"read-{name}", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.popen.stdout is not None
        for raw in iter(self.popen.stdout.readline, b""):
            self.output.append(raw.decode("utf-8", errors="replace").rstrip("\r\n"))
        self.output.close()

    @property
    def returncode(self) -> int | None:
        return self.popen.poll()

    def send_line(self, line: str) -> None:
        assert self.popen.stdin is not None
        self.popen.stdin.write(line.encode() + b"\n")
        self.popen.stdin.flush()

    def describe(self) -> str:
        return (
            f"{self.name} (pid {self.popen.pid}, exit code {self.returncode}) "
            f"ran {' '.join(self.argv)}\n--- output ---\n{self.output.text()}\n--- end of output ---"
        )

    def stop(self, timeout_s: float, *, end_of_input_first: bool = False) -> tuple[int | None, bool]:
        """Ask the process to stop, then make sure it has: SIGKILL to its group after `timeout_s`.

        The polite request is SIGTERM, or with `end_of_input_first` closing its stdin (for an
        interactive program blocked reading commands), then SIGTERM. Returns (exit code after the
        polite request, None if it had to be killed; whether it had exited before stop()).
        """
        already_exited = self.popen.poll() is not None
        code: int | None = self.popen.returncode
        if not already_exited:
            requests = [self._close_stdin, self._terminate] if end_of_input_first else [self._terminate]
            for request in requests:
                request()
                try:
                    code = self.popen.wait(timeout_s)
                    break
                except subprocess.TimeoutExpired:
                    code = None
        self._kill_group()
        if self.popen.poll() is None:
            self.popen.kill()
        self.popen.wait(PROCESS_KILL_WAIT_S)
        self._reader.join(PROCESS_KILL_WAIT_S)
        self._close_stdin()
        if self.popen.stdout is not None:
            self.popen.stdout.close()
        return code, already_exited

    def _close_stdin(self) -> None:
        if self.popen.stdin is not None and not self.popen.stdin.closed:
            try:
                self.popen.stdin.close()
            except OSError:
                pass

    def _terminate(self) -> None:
        try:
            self.popen.send_signal(signal.SIGTERM)
        except ProcessLookupError:
            pass

    def _kill_group(self) -> None:
        # The child leads its own session; anything it left running is in that process group.
        try:
            os.killpg(self.popen.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass


@pytest.fixture
def spawn(tmp_path: Path) -> Iterator[Callable[..., SpawnedProcess]]:
    """Factory: spawn(argv, name=..., cwd=tmp_path, env_overrides=None) -> SpawnedProcess.

    Children are stopped with SIGTERM at teardown (5 s, then SIGKILL to their process group)
    unless the test stopped them itself.
    """
    started: list[SpawnedProcess] = []

    def start(
        argv: list[str],
        *,
        name: str | None = None,
        cwd: Path | None = None,
        env_overrides: dict[str, str] | None = None,
    ) -> SpawnedProcess:
        env = dict(os.environ)
        env["PYTHONUNBUFFERED"] = "1"  # every line reaches us when it is printed
        env.update(env_overrides or {})
        process = SpawnedProcess(name or Path(argv[0]).name, argv, cwd or tmp_path, env)
        started.append(process)
        return process

    yield start
    for process in reversed(started):
        # MAVProxy reads its commands from stdin and does not act on SIGTERM while it waits
        # there: closing its input is what ends it (otherwise every teardown waits 5 s)
        process.stop(PROCESS_KILL_WAIT_S, end_of_input_first=process.name.startswith("mavproxy"))


# ---------------------------------------------------------------------------------------------
# gcsd


@pytest.fixture
def home_position() -> HomePosition:
    """Where the default simulated copter starts (it is disarmed there, on the ground)."""
    return DEFAULT_HOME


def _merged(base: dict, overrides: dict) -> dict:
    """Deep merge of mappings; any other value (lists included) in `overrides` replaces."""
    result = copy.deepcopy(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(result.get(key), dict):
            result[key] = _merged(result[key], value)
        else:
            result[key] = copy.deepcopy(value)
    return result


class GcsdDaemon:
    """A running `python -m gcsd run -c CONFIG`."""

    def __init__(self, process: SpawnedProcess, config_path: Path, config: dict) -> None:
        self.process = process
        self.config_path = config_path
        self.config = config
        self.addresses: dict[str, tuple[str, int]] = {}

    def port(self, channel_name: str) -> int:
        """The real port of a channel, as the daemon reported it in `channel_opened`."""
        assert channel_name in self.addresses, (
            f"no channel_opened event for channel {channel_name!r}; "
            f"opened: {sorted(self.addresses)}\n{self.process.describe()}"
        )
        return self.addresses[channel_name][1]

    def events(self, name: str | None = None) -> list[dict]:
        """The JSON log records printed so far (optionally only those with this `event`)."""
        records = []
        for _, line in self.process.output.lines():
            try:
                record = json.loads(line)
            except ValueError:
                continue
            if isinstance(record, dict) and (name is None or record.get("event") == name):
                records.append(record)
        return records

    def describe(self) -> str:
        return f"config {self.config_path}:\n{yaml.safe_dump(self.config)}\n{self.process.describe()}"


def _server_channel_names(config: dict) -> set[str]:
    channels = config.get("channels") or []
    return {c["name"] for c in channels if str(c.get("type", "")).endswith("-server")}


def _wait_until_channels_open(daemon: GcsdDaemon, expected: set[str], timeout_s: float) -> None:
    """Collect `channel_opened` events until every expected channel (or, if none, any) opened."""
    output = daemon.process.output
    deadline = time.monotonic() + timeout_s
    index = 0
    while True:
        found = output.wait_for(r'"channel_opened"', max(0.0, deadline - time.monotonic()), since=index)
        if found is None:
            break
        index, _, _ = found
        _, line = output.lines(index)[0]
        index += 1
        try:
            record = json.loads(line)
        except ValueError:
            continue
        if record.get("event") != "channel_opened":
            continue
        host, _, port = str(record["address"]).rpartition(":")
        daemon.addresses[record["channel"]] = (host, int(port))
        if expected <= set(daemon.addresses) and daemon.addresses:
            return
    missing = sorted(expected - set(daemon.addresses)) or ["(any channel)"]
    pytest.fail(
        f"gcsd did not report channel_opened for {missing} within {timeout_s} s\n{daemon.describe()}",
        pytrace=False,
    )


@pytest.fixture
def gcsd_daemon(tmp_path: Path, spawn) -> Iterator[Callable[..., GcsdDaemon]]:
    """Factory: gcsd_daemon(config_overrides=None, name="gcsd") -> GcsdDaemon (already listening).

    At teardown each daemon gets SIGTERM and must exit 0 within 5 s; otherwise the test errors
    with the daemon's output.
    """
    daemons: list[GcsdDaemon] = []

    def start(config_overrides: dict | None = None, *, name: str = "gcsd") -> GcsdDaemon:
        base = {
            "state_dir": str(tmp_path / name / "state"),
            "log": {"level": "info", "format": "json"},
            "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}],
        }
        config = _merged(base, config_overrides or {})
        config_path = tmp_path / f"{name}.yaml"
        config_path.write_text(yaml.safe_dump(config, sort_keys=False))
        # A PYTHONPATH from the environment comes first (to test another build); the working
        # tree's src/ is the fallback when gcsd is not installed in this interpreter.
        pythonpath = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
        pythonpath.append(str(REPO_ROOT / "src"))
        process = spawn(
            [sys.executable, "-m", "gcsd", "run", "-c", str(config_path)],
            name=name,
            cwd=tmp_path,
            env_overrides={"PYTHONPATH": os.pathsep.join(pythonpath)},
        )
        daemon = GcsdDaemon(process, config_path, config)
        # Failing here reports the start-up; the spawn fixture still stops the process.
        _wait_until_channels_open(daemon, _server_channel_names(config), GCSD_START_TIMEOUT_S)
        daemons.append(daemon)
        return daemon

    yield start

    problems = []
    for daemon in reversed(daemons):
        code, already_exited = daemon.process.stop(GCSD_STOP_TIMEOUT_S)
        if already_exited:
            problems.append(f"gcsd exited by itself (status {code}) before the test ended")
        elif code is None:
            problems.append(f"gcsd did not exit within {GCSD_STOP_TIMEOUT_S} s of SIGTERM")
        elif code != 0:
            problems.append(f"gcsd exited with status {code} on SIGTERM (a clean stop is 0)")
        else:
            continue
        problems[-1] += "\n" + daemon.describe()
    if problems:
        pytest.fail("\n\n".join(problems), pytrace=False)


# ---------------------------------------------------------------------------------------------
# MAVProxy, shared by the interop tests that drive it


def mavproxy_script() -> str:
    """mavproxy.py from this interpreter's environment (skip the test if it is not installed)."""
    script = shutil.which("mavproxy.py", path=str(Path(sys.executable).parent)) or shutil.which("mavproxy.py")
    if script is None:
        pytest.skip("mavproxy.py is not on PATH")
    return script


def mavproxy_for_params(spawn, port: int, cwd: Path) -> SpawnedProcess:
    """MAVProxy with its param module alone (FTP off), a ground station of vehicle 1:1 on
    udpout:127.0.0.1:PORT, once it has detected the vehicle."""
    mavproxy = spawn(
        [sys.executable, mavproxy_script(), f"--master=udpout:127.0.0.1:{port}", "--no-state",
         "--target-system=1", "--target-component=1", "--default-modules=param", "--cmd=set param_ftp 0"],
        name="mavproxy", cwd=cwd, env_overrides={"HOME": str(cwd)},
    )
    assert mavproxy.output.wait_for(re.compile(r"Detected vehicle 1:1"), 15.0) is not None, mavproxy.describe()
    return mavproxy


def expect_line(process: SpawnedProcess, daemon, pattern: str, timeout_s: float, since: int, what: str):
    """The first output line of `process` after `since` matching `pattern`, or a failure that
    shows both the process's and the daemon's output."""
    found = process.output.wait_for(pattern, timeout_s, since=since)
    if found is None:
        pytest.fail(
            f"{process.name} did not print {what} (/{pattern}/) within {timeout_s} s\n"
            f"{process.describe()}\n\n{daemon.describe()}",
            pytrace=False,
        )
    return found
