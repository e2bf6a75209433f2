"""Issue 17 item 8: a second `gcsd run` on the same state_dir exits 1 with a clear line before
it touches anything: the running daemon's control socket is not unlinked or rebound (so
`gcsd status` still reaches it), mav.parm is not rewritten (no STAT_BOOTCNT bump).

Both daemons are real `gcsd run` processes on one configuration, as an operator starts them.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

from gcsd.api import control

from .test_service import env_with_venv, free_udp_port, stop, write_config

START_TIMEOUT_S = 10.0


def wait_answering(sock, proc, timeout_s: float = START_TIMEOUT_S) -> dict:
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return control.query(sock, timeout_s=1.0)
        except (OSError, ValueError):
            if proc.poll() is not None or time.monotonic() > deadline:
                raise
            time.sleep(0.05)


def test_a_second_daemon_on_the_same_state_dir_exits_at_once_and_changes_nothing(tmp_path):
    cfg = write_config(tmp_path, free_udp_port())
    state = tmp_path / "state"
    first = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(cfg)], env=env_with_venv(),
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        sock = state / control.SOCKET_NAME
        wait_answering(sock, first)
        parm = state / "mav.parm"
        deadline = time.monotonic() + START_TIMEOUT_S  # the boot count is written behind, within a second
        while not parm.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        before = (parm.read_bytes(), parm.stat().st_mtime_ns, sock.stat().st_ino)

        second = subprocess.run([sys.executable, "-m", "gcsd", "run", "-c", str(cfg)], env=env_with_venv(), check=False,
                                capture_output=True, text=True, timeout=30)
        assert second.returncode == 1
        assert (parm.read_bytes(), parm.stat().st_mtime_ns, sock.stat().st_ino) == before, \
            "the socket was not rebound, mav.parm not rewritten"
        assert f"in use by another gcsd (pid {first.pid})" in second.stderr, second.stderr
        assert first.poll() is None
        assert wait_answering(sock, first, 3.0)["vehicles"], "gcsd status still reaches the running daemon"
        assert stop(first) == 0
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()

    third = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(cfg)], env=env_with_venv(),
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:  # positive control: once the first one stopped, the same configuration starts
        assert wait_answering(state / control.SOCKET_NAME, third)["vehicles"]
        assert (state / "gcsd.lock").read_text().strip() == str(third.pid)
    finally:
        assert stop(third) == 0
    assert os.path.exists(state / "gcsd.lock"), "the lock file stays; the lock went with the process"
