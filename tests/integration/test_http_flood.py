"""Issue 26 item 2: 1 100 TCP connections to the HTTP port that send nothing, against a real
`gcsd run` held to systemd's default 1 024 descriptors. On 63f9fa5 the API's listener was outside
the descriptor budget and a connection waited for its request head for an hour: the daemon
reached 1 024 descriptors, `gcsd status` was reset, an HTTP request got nothing (and a parameter
save would have failed with EMFILE). Now the API holds at most MAX_CONNECTIONS: each new one
closes the oldest that has not sent a request head (counted, `idle_replaced`), and one that sits
idle is closed after KEEPALIVE_S. In the same window (the positive controls) an HTTP client that
asks is answered, `gcsd status` answers, and a parameter written over HTTP is saved to mav.parm.
"""

from __future__ import annotations

import json
import os
import resource
import socket
import subprocess
import sys
import time
from pathlib import Path

from gcsd.api import control
from gcsd.api.http.service import ACCEPT_BACKLOG, KEEPALIVE_S, MAX_CONNECTIONS
from gcsd.links.tcpserver import FD_RESERVE

from .http_client import call, poll
from .test_service import env_with_venv, stop
from .test_state_lock import wait_answering

IDLE = 1100
DESCRIPTORS = 1024  # systemd's default soft limit for a service (LimitNOFILE=1024:524288)


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def descriptors(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/fd"))


def still_open(s: socket.socket) -> bool:
    s.setblocking(False)
    try:
        return s.recv(1, socket.MSG_PEEK) != b""
    except BlockingIOError:
        return True
    except OSError:
        return False


def test_a_thousand_idle_http_connections_leave_the_api_and_status_answering(tmp_path):
    http_port, udp_port = free_port(), free_port(socket.SOCK_DGRAM)
    cfg = tmp_path / "gcsd.yaml"
    cfg.write_text(f"state_dir: {tmp_path / 'state'}\nlog: {{level: info, format: json}}\n"
                   f"http: {{address: '127.0.0.1:{http_port}'}}\n"
                   f"channels:\n  - {{name: gcs, type: udp-server, address: '127.0.0.1:{udp_port}'}}\n")
    log_path = tmp_path / "gcsd.log"
    with log_path.open("wb") as log:
        proc = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(cfg)], env=env_with_venv(),
                                stdout=log, stderr=subprocess.STDOUT)
    resource.prlimit(proc.pid, resource.RLIMIT_NOFILE, (DESCRIPTORS, DESCRIPTORS))
    idle: list[socket.socket] = []
    url = f"http://127.0.0.1:{http_port}"
    try:
        sock_path = tmp_path / "state" / control.SOCKET_NAME
        wait_answering(sock_path, proc)
        assert poll(lambda: call(f"{url}/v1/status")[0] == 200)
        baseline = descriptors(proc.pid)
        for _ in range(IDLE):  # from another loopback address, as from another host
            idle.append(socket.create_connection(("127.0.0.1", http_port), timeout=2.0,
                                                 source_address=("127.0.0.2", 0)))
        held = descriptors(proc.pid)
        assert held <= baseline + MAX_CONNECTIONS + 2 < FD_RESERVE + MAX_CONNECTIONS + ACCEPT_BACKLOG, held
        assert call(f"{url}/v1/status", timeout=3.0)[0] == 200  # a client that asks is served
        status = control.query(sock_path, timeout_s=3.0)  # gcsd status answers
        http = status["http"]
        assert http["connections"] <= MAX_CONNECTIONS == http["max_connections"]
        assert http["refused"]["idle_replaced"] >= IDLE - MAX_CONNECTIONS - 2, http
        status, _, body, _ = call(f"{url}/v1/vehicles/1/parameters/ANGLE_MAX", "PUT", {"value": 3210})
        assert (status, body["value"]) == (200, 3210.0)
        parm = tmp_path / "state" / "mav.parm"
        assert poll(lambda: "ANGLE_MAX" in parm.read_text() and "3210" in parm.read_text()
                    if parm.exists() else False, timeout=8.0), "the parameter was saved"
        # the idle connections still held are closed by the daemon within KEEPALIVE_S
        assert poll(lambda: not any(still_open(s) for s in idle), timeout=KEEPALIVE_S + 3.0)
        assert call(f"{url}/v1/status")[0] == 200
        assert descriptors(proc.pid) <= baseline + 2
        events = [json.loads(line).get("event") for line in log_path.read_text().splitlines() if line.startswith("{")]
        assert "component_failed" not in events and "accept_failed" not in events
        assert proc.poll() is None
    finally:
        for s in idle:
            s.close()
        if proc.poll() is None:
            assert stop(proc) == 0
