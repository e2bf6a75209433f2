"""Channels at run time (SPEC.md "Companion routing"): `gcsd channel add|remove` through the
control socket, channels.yaml restored at the next start, and the SIGHUP reload of a real daemon
process. In each, a ground station on an untouched channel keeps receiving throughout (no gap)
and keeps its peer, route and counters."""

from __future__ import annotations

import itertools
import json
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import yaml

from gcsd.api import control

from .helpers import VEHICLE, Client, M, from_vehicle, udp_channel, udp_url, wait_for

GAP_LIMIT_S = 1.0  # the vehicle's streams come at 2-5 Hz and HEARTBEAT at 1 Hz: a second of nothing is a gap


def _cli(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "gcsd", *argv], capture_output=True, text=True, timeout=60,
                          check=False)


def _status(socket_path: Path) -> dict:
    return control.query(socket_path)


def _by_name(status: dict) -> dict[str, dict]:
    return {c["name"]: c for c in status["channels"]}


def _max_gap_s(c: Client, mark: int) -> float:
    times = [r.t for r in c.since(mark) if r.src == VEHICLE]
    return max((b - a for a, b in itertools.pairwise(times)), default=float("inf"))


def _keep_reading(c: Client, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        c.read_available()
        time.sleep(0.02)


def _run_cli_while_reading(c: Client, *argv: str) -> subprocess.CompletedProcess:
    """The CLI in the background while the untouched channel's station goes on reading (its
    frames are timed when read: a pause in reading would look like a gap)."""
    proc = subprocess.Popen([sys.executable, "-m", "gcsd", *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    while proc.poll() is None:
        c.read_available()
        time.sleep(0.02)
    out, err = proc.communicate()
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def test_channel_add_and_remove_at_run_time_leave_the_other_channels_alone(daemon, client, tmp_path):
    d = daemon({"channels": [udp_channel("gcs")]})
    conf = tmp_path / "gcsd.yaml"
    conf.write_text(yaml.safe_dump({"state_dir": d.config.state_dir.as_posix(), "channels": [udp_channel("gcs")]}))
    sock = Path(d.config.state_dir) / control.SOCKET_NAME
    station = client(udp_url(d.port("gcs")), 255, 190)
    station.heartbeat()
    assert wait_for(station, from_vehicle)
    before = _by_name(_status(sock))["gcs"]
    mark = station.mark()

    added = _run_cli_while_reading(station, "channel", "add", "-c", str(conf), "lte", "udp-server", "127.0.0.1:0")
    assert added.returncode == 0, added.stderr
    lte = _by_name(_status(sock))["lte"]
    second = client(udp_url(int(lte["address"].rsplit(":", 1)[1])), 254, 190)
    second.heartbeat()
    assert wait_for(second, from_vehicle, others=[station]), "the added channel does not serve"
    saved = yaml.safe_load((Path(d.config.state_dir) / "channels.yaml").read_text())
    assert saved == {"channels": [{"name": "lte", "type": "udp-server", "address": "127.0.0.1:0"}]}

    refused = _run_cli_while_reading(station, "channel", "add", "-c", str(conf), "bad", "udp-server", "nowhere")
    assert refused.returncode == 2
    assert refused.stderr.strip() == "gcsd channel add: address: expected HOST:PORT, got 'nowhere'"
    clash = _run_cli_while_reading(station, "channel", "add", "-c", str(conf), "gcs", "udp-client", "127.0.0.1:9")
    assert clash.returncode == 2 and "already running" in clash.stderr

    removed = _run_cli_while_reading(station, "channel", "remove", "-c", str(conf), "lte")
    assert removed.returncode == 0, removed.stderr
    _keep_reading(station, 0.5)
    after = _status(sock)
    assert "lte" not in _by_name(after)
    assert yaml.safe_load((Path(d.config.state_dir) / "channels.yaml").read_text()) == {"channels": []}
    gcs = _by_name(after)["gcs"]
    assert gcs["peers"] == 1 and gcs["packets_in"] >= before["packets_in"] and gcs["packets_out"] > before["packets_out"]
    assert {"sysid": 255, "compid": 190, "channel": "gcs"}.items() <= next(
        r for r in after["routes"] if r["sysid"] == 255).items()
    assert _max_gap_s(station, mark) < GAP_LIMIT_S
    listed = _cli("channel", "list", "-c", str(conf), "--json")
    assert [c["name"] for c in json.loads(listed.stdout)] == ["gcs", "http"]  # http: the API's own channel
    table = _cli("channel", "list", "-c", str(conf)).stdout.splitlines()
    assert table[0] == "Channels" and table[1].split()[:3] == ["channel", "type", "address"]
    assert [row.split()[0] for row in table[3:]] == ["gcs", "http"]


def test_channels_added_at_run_time_are_restored_at_the_next_start(daemon, client, tmp_path):
    state = tmp_path / "state"
    state.mkdir()
    (state / "channels.yaml").write_text(yaml.safe_dump({"channels": [
        {"name": "lte", "type": "udp-server", "address": "127.0.0.1:0"},
        {"name": "clash", "type": "udp-server", "address": "127.0.0.1:0", "options": ["nonsense"]},
    ]}))
    d = daemon({"channels": [udp_channel("gcs")]})
    names = [c["name"] for c in d.status()["channels"]]
    assert names == ["gcs", "lte", "http"]  # the bad entry is skipped (and logged), the good one restored
    station = client(udp_url(d.port("lte")), 255, 190)
    station.heartbeat()
    assert wait_for(station, from_vehicle)


# --- SIGHUP: a real daemon process -------------------------------------------------------------

def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _write(conf: Path, state: Path, channels: list[dict]) -> None:
    conf.write_text(yaml.safe_dump({"state_dir": str(state), "log": {"level": "info", "format": "json"},
                                    "channels": channels}))


def test_sighup_reloads_the_channels_and_a_bad_file_changes_nothing(tmp_path, client):
    conf, state = tmp_path / "gcsd.yaml", tmp_path / "state"
    gcs_port, old_port, new_port = _free_port(), _free_port(), _free_port()
    gcs = {"name": "gcs", "type": "udp-server", "address": f"127.0.0.1:{gcs_port}"}
    _write(conf, state, [gcs, {"name": "old", "type": "udp-server", "address": f"127.0.0.1:{old_port}"}])
    proc = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(conf)], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)  # the JSON log lines
    try:
        station = client(udp_url(gcs_port), 255, 190)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not station.since(0):
            station.heartbeat()
            _keep_reading(station, 0.2)
        assert wait_for(station, from_vehicle), "the daemon did not start"
        sock = state / control.SOCKET_NAME
        before = _by_name(_status(sock))["gcs"]
        mark = station.mark()

        _write(conf, state, [gcs, {"name": "new", "type": "udp-server", "address": f"127.0.0.1:{new_port}"}])
        proc.send_signal(signal.SIGHUP)
        newcomer = client(udp_url(new_port), 254, 190)
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and not [r for r in newcomer.since(0) if r.src == VEHICLE]:
            newcomer.heartbeat()
            station.read_available()
            _keep_reading(newcomer, 0.1)
        assert [r for r in newcomer.since(0) if r.src == VEHICLE], "the channel added to the file never opened"
        _keep_reading(station, 0.5)
        after = _status(sock)
        assert sorted(_by_name(after)) == ["gcs", "http", "new"]  # http: the API's own channel
        kept = _by_name(after)["gcs"]
        assert kept["peers"] == 1 and kept["packets_in"] >= before["packets_in"]
        assert kept["packets_out"] > before["packets_out"]
        assert any(r["sysid"] == 255 and r["channel"] == "gcs" for r in after["routes"])
        assert _max_gap_s(station, mark) < GAP_LIMIT_S
        before_reopen = _by_name(after)["new"]["packets_in"]

        # a changed channel is reopened in its slot; the untouched one still sees no gap
        mark = station.mark()
        _write(conf, state, [gcs, {"name": "new", "type": "udp-server", "address": f"127.0.0.1:{new_port}",
                                   "rate_limits": {"ATTITUDE": 1}}])
        proc.send_signal(signal.SIGHUP)
        deadline = time.monotonic() + 5
        reopened = None
        while time.monotonic() < deadline and reopened is None:
            _keep_reading(station, 0.1)
            reopened = _by_name(_status(sock)).get("new")
            reopened = reopened if reopened is not None and reopened["packets_in"] < before_reopen else None
        assert reopened is not None, "the changed channel was not reopened (its counters did not restart)"
        newcomer.heartbeat()
        assert wait_for(newcomer, from_vehicle, since=newcomer.mark(), others=[station]), "the reopened channel"
        _keep_reading(station, 1.5)  # a window longer than the gap limit
        assert _max_gap_s(station, mark) < GAP_LIMIT_S
        assert _by_name(_status(sock))["gcs"]["peers"] == 1

        conf.write_text("channels: [{name: gcs, type: udp-server, address: nowhere}]\n")
        proc.send_signal(signal.SIGHUP)
        mark = newcomer.mark()
        newcomer.command_long(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        assert wait_for(newcomer, lambda r: r.type == "COMMAND_ACK" and r.src == VEHICLE, since=mark)
        assert sorted(_by_name(_status(sock))) == ["gcs", "http", "new"]  # nothing changed
        assert proc.poll() is None
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            out, _ = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
    assert proc.returncode == 0
    reloads = [json.loads(line) for line in out.splitlines() if '"configuration_reloaded"' in line]
    assert [(r["closed"], r["reopened"], r["opened"]) for r in reloads] == [(["old"], [], ["new"]), ([], ["new"], [])]
    refused = [json.loads(line) for line in out.splitlines() if '"reload_refused"' in line]
    assert [r["problem"] for r in refused] == [f"{conf}:1: channels[0].address: expected HOST:PORT, got 'nowhere'"]
