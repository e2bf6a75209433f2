"""Issue 17 item 10: SIGHUP never kills the daemon nor loses an acknowledged value.

On 21d5d2b SIGHUP's default action ended the process: no clean stop, no flush (a parameter
acknowledged 0.2 s earlier was lost), socket and registration left behind. Now it writes out
what was changed (`state_synced`), re-reads the configuration (the companion-routing reload,
`reload_requested`) and keeps serving. The daemon is a real `gcsd run` process; the value is
checked in mav.parm after a SIGKILL right after the SIGHUP's sync, inside the write-behind's
one-second window, so only the sync can have written it.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

from gcsd.api import control
from gcsd.vehicle.params.parmfile import read_parm

from .helpers import VEHICLE, Client, M, wait_for
from .test_service import env_with_venv, free_udp_port, stop, write_config
from .test_state_lock import wait_answering


def events(log_path, name: str) -> int:
    """How many log records of that event (JSON lines; a console line names the event in its text)."""
    count = 0
    for line in log_path.read_text(errors="replace").splitlines():
        try:
            count += json.loads(line).get("event") == name
        except ValueError:
            count += f" {name} " in line
    return count


def wait_event(log_path, name: str, count: int, proc: subprocess.Popen, timeout_s: float = 5.0) -> bool:
    """Whether the log holds `count` such events within the timeout (False at once if the process ended)."""
    deadline = time.monotonic() + timeout_s
    while events(log_path, name) < count:
        if time.monotonic() > deadline or proc.poll() is not None:
            return False
        time.sleep(0.02)
    return True


def set_param(c: Client, name: bytes, value: float) -> None:
    mark = c.mark()
    c.send(M.MAVLink_param_set_message(*VEHICLE, name, value, M.MAV_PARAM_TYPE_INT16))
    ack = wait_for(c, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == name.decode(), 3.0, mark)
    assert ack is not None and ack.msg.param_value == value, "acknowledged"


def test_sighup_keeps_the_daemon_serving_and_writes_out_what_was_acknowledged(tmp_path):
    port = free_udp_port()
    cfg = write_config(tmp_path, port)
    log_path = tmp_path / "gcsd.log"
    with log_path.open("wb") as log:
        proc = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(cfg)], env=env_with_venv(),
                                stdout=log, stderr=subprocess.STDOUT)
    gcs = Client(f"udpout:127.0.0.1:{port}", 255, 190)
    try:
        sock = tmp_path / "state" / control.SOCKET_NAME
        wait_answering(sock, proc)
        gcs.heartbeat()
        set_param(gcs, b"RC7_TRIM", 1501)
        set_param(gcs, b"RC7_TRIM", 1502)  # within a second of the first: waits on the write-behind timer

        proc.send_signal(signal.SIGHUP)
        synced = wait_event(log_path, "state_synced", 1, proc)
        assert proc.poll() is None, f"SIGHUP ended the daemon (exit {proc.returncode})"
        assert synced, "SIGHUP wrote out the state"
        assert wait_event(log_path, "reload_requested", 1, proc), "and asked for the configuration's reload"
        assert wait_answering(sock, proc, 3.0)["vehicles"], "gcsd status still answers"
        mark = gcs.mark()
        gcs.heartbeat()
        assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE, 3.0, mark), "still serving"

        set_param(gcs, b"RC7_TRIM", 1503)
        proc.send_signal(signal.SIGHUP)
        assert wait_event(log_path, "state_synced", 2, proc)
        proc.kill()  # no clean stop: what is on disk is what the SIGHUP wrote
        proc.wait(5)
        assert read_parm(tmp_path / "state" / "mav.parm")[0]["RC7_TRIM"] == 1503
    finally:
        gcs.close()
        if proc.poll() is None:
            stop(proc)


def test_sighup_never_ends_an_embedding_program(tmp_path):
    robot = Path(__file__).resolve().parents[2] / "sitl" / "embed_robot.py"
    port = free_udp_port()
    log_path = tmp_path / "robot.log"
    with log_path.open("wb") as log:
        proc = subprocess.Popen([sys.executable, str(robot), "--port", str(port), "--state-dir",
                                 str(tmp_path / "robot")], env=env_with_venv(PYTHONUNBUFFERED="1"), stdout=log,
                                stderr=subprocess.STDOUT)
    gcs = Client(f"udpout:127.0.0.1:{port}", 255, 190)
    try:
        wait_answering(tmp_path / "robot" / control.SOCKET_NAME, proc)
        gcs.heartbeat()
        assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE, 5.0), "serving"
        proc.send_signal(signal.SIGHUP)
        synced = wait_event(log_path, "state_synced", 1, proc)
        assert proc.poll() is None, f"SIGHUP ended the program (exit {proc.returncode})"
        assert synced, "it wrote out its state"
        mark = gcs.mark()
        gcs.heartbeat()
        assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE, 3.0, mark), "still serving"
    finally:
        gcs.close()
        if proc.poll() is None:
            stop(proc)
