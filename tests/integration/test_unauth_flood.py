"""Issue 17 item 3: 1 100 idle TCP connections to a tcp-server that requires signing, against a
real `gcsd run` held to systemd's default 1 024 descriptors. On 21d5d2b the waiting connections
were neither counted against max_peers nor timed out: the daemon ran out of descriptors, a
signed ground station got nothing, `gcsd status` timed out, and accept() failures spun at
100 % CPU with a traceback each. Now they are bounded (max_peers, one waiting slot always left),
the oldest are closed and counted (`unauthenticated_closed`), and in the same window a signed
station is served and `gcsd status` answers (the positive controls). The same flood where no
signature is needed: connections are served at once there, bounded by max_peers, and an idle
one is the first replaced.
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

import pytest

from gcsd.api import control

from .helpers import Client, tcp_url
from .test_service import env_with_venv, stop
from .test_signing import KEY, arm_ack, sign
from .test_state_lock import wait_answering

IDLE = 1100
DESCRIPTORS = 1024  # systemd's default soft limit for a service (LimitNOFILE=1024:524288)


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@pytest.mark.parametrize("signed", [True, False], ids=["signing-required", "no-signing"])
def test_a_thousand_idle_connections_leave_a_station_served_and_status_answering(tmp_path, signed):
    port = free_tcp_port()
    cfg = tmp_path / "gcsd.yaml"
    signing = f"signing: {{key: {KEY.hex()}, require: true}}\n" if signed else ""
    cfg.write_text(f"state_dir: {tmp_path / 'state'}\nlog: {{level: info, format: json}}\n{signing}"
                   f"channels:\n  - {{name: gcs, type: tcp-server, address: '127.0.0.1:{port}'}}\n")
    log_path = tmp_path / "gcsd.log"
    with log_path.open("wb") as log:
        proc = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(cfg)], env=env_with_venv(),
                                stdout=log, stderr=subprocess.STDOUT)
    resource.prlimit(proc.pid, resource.RLIMIT_NOFILE, (DESCRIPTORS, DESCRIPTORS))  # long before the flood
    idle: list[socket.socket] = []
    station = None
    try:
        sock_path = tmp_path / "state" / control.SOCKET_NAME
        wait_answering(sock_path, proc)
        low_fd = socket.socket()  # keeps a descriptor below 1024 for the station (helpers use select())
        refused = 0
        for _ in range(IDLE):  # from another loopback address than the station's, as from another host
            try:
                idle.append(socket.create_connection(("127.0.0.1", port), timeout=2.0,
                                                     source_address=("127.0.0.2", 0)))
            except OSError:
                refused += 1
        assert refused < IDLE // 10, f"{refused} connections were not even accepted by the kernel"

        cpu_before, t_before = cpu_s(proc.pid), time.monotonic()
        low_fd.close()
        station = Client(tcp_url(port), 255, 190)
        if signed:
            sign(station, KEY)
        assert arm_ack(station, timeout=5.0) is not None, "a station is served"
        status = control.query(sock_path, timeout_s=3.0)  # gcsd status answers
        gcs = next(c for c in status["channels"] if c["name"] == "gcs")
        assert gcs["peers"] == (1 if signed else 8), "the station (without signing, max_peers: idle ones are served too)"
        assert gcs["unauthenticated_closed"] >= len(idle) - 8, gcs
        descriptors = len(os.listdir(f"/proc/{proc.pid}/fd"))
        assert descriptors < 100, f"the daemon holds {descriptors} descriptors"
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:  # a window in which the station keeps being served
            station.read_available()
            time.sleep(0.05)
        busy = (cpu_s(proc.pid) - cpu_before) / (time.monotonic() - t_before)
        assert busy < 0.5, f"the daemon used {busy:.0%} of a core while the connections sat idle"
        events = [json.loads(line).get("event") for line in log_path.read_text().splitlines() if line.startswith("{")]
        assert events.count("accept_failed") == 0 and "component_failed" not in events
        assert proc.poll() is None
    finally:
        for s in idle:
            s.close()
        if station is not None:
            station.close()
        if proc.poll() is None:
            assert stop(proc) == 0
