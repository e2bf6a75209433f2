"""gcsd as a service: the systemd unit's own command under a notify socket, the watchdog, a clean
stop, `gcsd status`, and tlog files that pymavlink reads."""

from __future__ import annotations

import json
import os
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest
from pymavlink import mavutil

from .helpers import M, await_ready, notify_socket, pump, udp_url

REPO = Path(__file__).resolve().parents[2]
UNIT = REPO / "systemd" / "gcsd.service"


def unit_exec_start() -> list[str]:
    for line in UNIT.read_text().splitlines():
        if line.startswith("ExecStart="):
            return shlex.split(line.split("=", 1)[1])
    raise AssertionError("no ExecStart in the unit")


def write_config(tmp_path: Path, port: int = 0, extra: str = "", tail: str = "") -> Path:
    """gcsd.yaml with a udp-server `gcs` on `port`; `extra` goes into `log`, `tail` after `gcs`."""
    cfg = tmp_path / "gcsd.yaml"
    cfg.write_text(
        f"state_dir: {tmp_path / 'state'}\nlog: {{level: info, format: json{extra}}}\n"
        f"channels:\n  - {{name: gcs, type: udp-server, address: '127.0.0.1:{port}'}}\n{tail}"
    )
    return cfg


def env_with_venv(**extra: str) -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = str(Path(sys.executable).parent) + os.pathsep + env.get("PATH", "")
    env.update(extra)
    return env


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(proc: subprocess.Popen) -> int:
    proc.send_signal(signal.SIGTERM)
    try:
        return proc.wait(5)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_unit_file_passes_systemd_analyze_verify():
    tool = shutil.which("systemd-analyze")
    if tool is None:
        if os.environ.get("CI"):
            pytest.fail("systemd-analyze is missing: .ci/run installs systemd")
        pytest.skip("systemd-analyze is not installed")
    result = subprocess.run([tool, "verify", str(UNIT)], check=False, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr


def test_exec_start_under_systemd_notify_sends_ready_then_watchdog_pings_then_stopping(tmp_path):
    """Every message is awaited, none timed: a start or a ping that comes late on a loaded machine
    is no failure (Notifier's interval, half of WATCHDOG_USEC, is pinned in tests/unit/test_notify.py).
    Pings cannot come early, so four of them spanning three intervals shows they are paced."""
    notify, notify_path = notify_socket(tmp_path)
    argv = unit_exec_start()
    argv[argv.index("/etc/gcsd/gcsd.yaml")] = str(write_config(tmp_path))
    interval_s = 0.3
    proc = subprocess.Popen(
        argv, env=env_with_venv(NOTIFY_SOCKET=str(notify_path), WATCHDOG_USEC=str(int(2 * interval_s * 1e6))),
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    try:
        assert "1 of 1 channels open" in await_ready(notify, proc)
        pings = [notify.recv(4096).decode() for _ in range(4)]
        started = time.monotonic()
        pings += [notify.recv(4096).decode() for _ in range(3)]
        paced_s = time.monotonic() - started
        assert stop(proc) == 0
        after = []
        while not after or after[-1] != "STOPPING=1":
            after.append(notify.recv(4096).decode())
    finally:
        if proc.poll() is None:
            proc.kill()
        notify.close()
    assert pings == ["WATCHDOG=1"] * 7, pings
    assert paced_s >= 3 * interval_s * 0.9, f"3 pings after the 4th in {paced_s:.2f} s: not paced"
    assert set(after[:-1]) <= {"WATCHDOG=1"}, after


def test_status_command_shows_channels_routes_and_vehicle(tmp_path):
    port = free_udp_port()
    cfg = write_config(tmp_path, port)
    notify, notify_path = notify_socket(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(cfg)],
                            env=env_with_venv(NOTIFY_SOCKET=str(notify_path)),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        await_ready(notify, proc)  # the UDP port is bound (the control socket exists before it is)
        gcs = mavutil.mavlink_connection(udp_url(port), source_system=255, source_component=190)
        gcs.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        heard = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10)
        gcs.close()
        assert heard is not None
        out = subprocess.run([sys.executable, "-m", "gcsd", "status", "-c", str(cfg)],
                             check=False, capture_output=True, text=True, timeout=10)
        assert out.returncode == 0, out.stderr
        assert f"127.0.0.1:{port}" in out.stdout
        assert "255    190" in out.stdout, out.stdout  # the learned route of the ground station
        assert "copter" in out.stdout and "STABILIZE" in out.stdout
    finally:
        assert stop(proc) == 0
        notify.close()
    assert not (tmp_path / "state" / "gcsd.sock").exists(), "the control socket is removed at stop"


def test_status_without_a_daemon_fails_clearly(tmp_path):
    cfg = write_config(tmp_path)
    out = subprocess.run([sys.executable, "-m", "gcsd", "status", "-c", str(cfg)],
                         check=False, capture_output=True, text=True, timeout=10)
    assert out.returncode == 1 and "no daemon answers" in out.stderr


def test_tlog_records_frames_in_both_directions_readably(daemon, client, tmp_path):
    tlog = tmp_path / "run.tlog"
    d = daemon({"log": {"tlog": str(tlog)},
                "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]})
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    c.command_long(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    pump([c], 1.5)
    d.stop()
    log = mavutil.mavlink_connection(str(tlog))
    seen = set()
    while (msg := log.recv_match()) is not None:
        seen.add((msg.get_type(), msg.get_srcSystem()))
    assert ("HEARTBEAT", 255) in seen and ("COMMAND_LONG", 255) in seen, "frames in"
    assert ("HEARTBEAT", 1) in seen and ("COMMAND_ACK", 1) in seen, "frames out"


def test_ready_is_not_held_back_by_a_flight_controller_that_is_down_at_boot(tmp_path):
    dead = socket.socket()
    dead.bind(("127.0.0.1", 0))
    fc_port = dead.getsockname()[1]
    dead.close()  # nothing listens there: the flight controller link cannot open
    cfg = write_config(tmp_path, tail=f"  - {{name: fc, type: tcp-client, address: '127.0.0.1:{fc_port}'}}\n")
    notify, notify_path = notify_socket(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(cfg)],
                            env=env_with_venv(NOTIFY_SOCKET=str(notify_path), WATCHDOG_USEC="600000"),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        # READY while the fc is down is the proof (its link never opens, so a READY held back
        # for it would never come); how soon it comes is the machine's load, not the daemon's rule
        first = await_ready(notify, proc)
        second = notify.recv(4096).decode()
        # gcs open, fc down (the API's own http channel is no MAVLink channel: not counted)
        assert "1 of 2 channels open" in first, first
        assert second == "WATCHDOG=1", "and the watchdog is fed"
        assert stop(proc) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
        notify.close()


def _status_json(cfg: Path) -> dict:
    out = subprocess.run([sys.executable, "-m", "gcsd", "status", "-c", str(cfg), "--json"],
                         check=False, capture_output=True, text=True, timeout=10)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def test_an_http_port_another_process_holds_costs_only_the_api_until_it_is_free(tmp_path):
    """A second gcsd on the host (a swarm, a fleet instance, a parallel test) must not lose READY
    or a MAVLink channel to the HTTP port: READY comes at once and says why the API is not
    listening, the MAVLink channel answers, the failure is one warning however many retries, and
    the API listens once the port is free (the positive control)."""
    holder = socket.socket()
    holder.bind(("127.0.0.1", 0))
    holder.listen()
    http_port = holder.getsockname()[1]
    cfg = write_config(tmp_path, tail=f"http: {{address: '127.0.0.1:{http_port}'}}\n")
    notify, notify_path = notify_socket(tmp_path)
    log_path = tmp_path / "gcsd.log"
    with log_path.open("wb") as log_file:
        proc = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(cfg)],
                                env=env_with_venv(NOTIFY_SOCKET=str(notify_path)),
                                stdout=log_file, stderr=subprocess.STDOUT)
    try:
        ready = await_ready(notify, proc)
        assert "1 of 1 channels open" in ready, ready
        assert f"HTTP API not listening on 127.0.0.1:{http_port}" in ready, ready
        status = _status_json(cfg)
        assert status["http"]["listening"] is None and status["http"]["error"], status["http"]
        gcs_port = int(next(c for c in status["channels"] if c["name"] == "gcs")["address"].rsplit(":", 1)[1])
        station = mavutil.mavlink_connection(udp_url(gcs_port), source_system=255, source_component=190)
        try:
            station.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            assert station.recv_match(type="HEARTBEAT", blocking=True, timeout=5) is not None, "MAVLink answers"
        finally:
            station.close()
        deadline = time.monotonic() + 10
        while (failures := _channel(_status_json(cfg), "http")["open_failures"]) < 2:
            assert time.monotonic() < deadline, "the API's listener is not retried"
            time.sleep(0.2)
        text = subprocess.run([sys.executable, "-m", "gcsd", "status", "-c", str(cfg)],
                              check=True, capture_output=True, text=True, timeout=10).stdout
        assert f"HTTP API: not listening on 127.0.0.1:{http_port}" in text, text
        holder.close()  # the other process lets go of the port
        deadline = time.monotonic() + 10  # the transport's backoff is capped at 5 s
        while _status_json(cfg)["http"]["listening"] != f"127.0.0.1:{http_port}":
            assert time.monotonic() < deadline, "the API never listened once the port was free"
            time.sleep(0.2)
        with urllib.request.urlopen(f"http://127.0.0.1:{http_port}/v1/status", timeout=5) as answer:
            assert json.loads(answer.read())["vehicles"][0]["sysid"] == 1
        assert stop(proc) == 0
    finally:
        holder.close()
        if proc.poll() is None:
            proc.kill()
        notify.close()
    events = [json.loads(line) for line in log_path.read_text().splitlines() if line.startswith("{")]
    warned = [e for e in events if e["event"] == "channel_open_failed" and e.get("channel") == "http"
              and e["level"] == "warning"]
    assert failures >= 2 and len(warned) == 1, (failures, warned)  # one warning for the same error


def _channel(status: dict, name: str) -> dict:
    return next(c for c in status["channels"] if c["name"] == name)
