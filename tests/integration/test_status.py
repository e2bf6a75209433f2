"""`gcsd status` finds a daemon started from another directory (the rule in control.py): a real
daemon process with a relative state_dir, asked from elsewhere with and without -c, its
registration removed at the stop; stale registrations ignored."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from pymavlink import mavutil

from gcsd.loop import loop_name
from gcsd.wire import speedups

from .helpers import M, udp_url

REPO = Path(__file__).resolve().parents[2]


def gcsd(*args: str, cwd: Path, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gcsd", *args], cwd=cwd, env=env, check=False, capture_output=True,
                          text=True, timeout=20)


@pytest.fixture
def env(tmp_path):
    """Its own runtime directory, so the test sees only its own daemons."""
    return {**os.environ, "PYTHONPATH": str(REPO / "src"), "XDG_RUNTIME_DIR": str(tmp_path / "run")}


@pytest.fixture
def running(tmp_path, env):
    """A daemon run as `gcsd -c g.yaml` from tmp_path/a, state_dir relative to there."""
    start_dir = tmp_path / "a"
    start_dir.mkdir()
    config = start_dir / "g.yaml"
    config.write_text("state_dir: ./state\nchannels:\n  - {name: gcs, type: udp-server, address: '127.0.0.1:0'}\n")
    proc = subprocess.Popen([sys.executable, "-m", "gcsd", "-c", "g.yaml"], cwd=start_dir, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    registry = tmp_path / "run" / "gcsd"
    deadline = time.monotonic() + 10
    while not list(registry.glob("*.json")) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert list(registry.glob("*.json")), f"no registration: {proc.poll()} {proc.stderr.read() if proc.poll() else ''}"
    yield proc, config, registry
    if proc.poll() is None:
        proc.kill()
        proc.wait()


def stop(proc: subprocess.Popen) -> int:
    proc.send_signal(signal.SIGTERM)
    return proc.wait(10)


def test_status_from_another_directory_finds_the_daemon_by_its_file_or_its_registration(running, tmp_path, env):
    proc, config, registry = running
    elsewhere = tmp_path / "b"
    elsewhere.mkdir()
    entry = json.loads(next(registry.glob("*.json")).read_text())
    assert entry == {"pid": proc.pid, "socket": str(tmp_path / "a" / "state" / "gcsd.sock"),
                     "state_dir": str(tmp_path / "a" / "state"), "config": str(config)}
    status = json.loads(gcsd("status", "-c", str(config), "--json", cwd=elsewhere, env=env).stdout)
    port = int(status["channels"][0]["address"].rsplit(":", 1)[1])
    assert status["runtime"] == {"loop": loop_name(), "speedups": speedups.IMPLEMENTATION}
    gcs = mavutil.mavlink_connection(udp_url(port), source_system=255, source_component=190)
    try:
        gcs.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        assert gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=3) is not None
    finally:
        gcs.close()
    by_file = gcsd("status", "-c", str(config), cwd=elsewhere, env=env)
    assert by_file.returncode == 0, by_file.stderr
    lines = by_file.stdout.splitlines()
    assert lines[0].startswith("gcsd ") and f"(pid {proc.pid}, config {config})" in lines[0]
    route = lines[lines.index("Routes learned") + 3].split()
    assert route[:4] == ["255", "190", "GCS", "gcs"]
    assert "Errors (exceptions caught, by component): none" in lines
    anywhere = gcsd("status", cwd=elsewhere, env=env)  # no -c, no ./gcsd-state here: the registered daemon
    assert anywhere.returncode == 0 and f"(pid {proc.pid}, config {config})" in anywhere.stdout
    other_config = elsewhere / "other.yaml"
    other_config.write_text("state_dir: ./state\n")
    wrong = gcsd("status", "-c", str(other_config), cwd=elsewhere, env=env)
    assert wrong.returncode == 1 and "no daemon started with" in wrong.stderr
    assert stop(proc) == 0
    assert list(registry.glob("*.json")) == [], "the registration is removed at a clean stop"
    gone = gcsd("status", "-c", str(config), cwd=elsewhere, env=env)
    assert gone.returncode == 1 and "no daemon answers" in gone.stderr


def test_a_registration_of_a_dead_process_is_ignored_and_removed(tmp_path, env):
    registry = tmp_path / "run" / "gcsd"
    registry.mkdir(parents=True, mode=0o700)
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = registry / f"{dead.pid}.json"
    stale.write_text(json.dumps({"pid": dead.pid, "socket": str(tmp_path / "nowhere.sock"), "config": None,
                                 "state_dir": str(tmp_path)}))
    result = gcsd("status", cwd=tmp_path, env=env)
    assert result.returncode == 1 and "no daemon answers" in result.stderr
    assert not stale.exists()
