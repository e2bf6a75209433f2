"""Issue 11 regressions: what a stranger or a sloppy ground station sends cannot change what the
daemon serves to others, fool signing, make it an amplifier, or stop it.

Every check that something did not happen has, in the same window, a positive control through
the same daemon (a served station keeps receiving, a fresh signed request is answered).
"""

from __future__ import annotations

import asyncio
import json
import socket
import subprocess
import sys
import threading
import time

import pytest
import yaml

from gcsd.config import parse_config
from gcsd.daemon.daemon import Daemon
from gcsd.vehicle.sim import Landed

from .helpers import VEHICLE, Client, M, is_ack, packed, pump, udp_channel, udp_url, wait_for
from .test_signing import KEY, answered_request, arm_ack, now_units, sign, signed_daemon

TEN_YEARS_UNITS = 10 * 365 * 24 * 3600 * 100_000


def vehicle_frames(c: Client, mark: int = 0) -> list[bytes]:
    return [r.raw for r in c.received[mark:] if r.src == VEHICLE]


def served(c: Client, seconds: float = 2.5) -> bool:
    """A vehicle HEARTBEAT reaches c within `seconds` (the positive control)."""
    return wait_for(c, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE, timeout=seconds,
                    since=c.mark()) is not None


# --- signing holds -------------------------------------------------------------------------

def test_a_strangers_unsigned_mavlink1_heartbeat_changes_nothing_for_the_signed_station(daemon, client, tmp_path):
    d = signed_daemon(daemon, tmp_path)
    station = client(udp_url(d.port("gcs")))
    sign(station, KEY)
    assert arm_ack(station) is not None
    stranger = client(udp_url(d.port("gcs")), 250, 190, version=1)
    mark = station.mark()
    for _ in range(5):
        stranger.heartbeat()
        pump([station, stranger], 0.3)
    assert served(station)
    frames = vehicle_frames(station, mark)
    assert frames and all(f[0] == 0xFD and f[2] & 0x01 for f in frames), "signed MAVLink2 only, all along"
    assert stranger.received == [] and stranger.bytes_in == 0, "the stranger is never served"
    assert d.stats("gcs")["peers"] == 1


def test_a_replay_is_refused_after_more_than_64_signed_streams_came_and_went(daemon, client, tmp_path):
    d = signed_daemon(daemon, tmp_path)
    station = client(udp_url(d.port("gcs")))
    sign(station, KEY)
    captured = answered_request(station)
    for i in range(70):  # 70 new streams: more than the table holds, the station's is evicted
        other = client(udp_url(d.port("gcs")), 200, 1 + i)
        sign(other, KEY, link_id=i)
        other.heartbeat()
        other.close()
    replays_before = d.stats("gcs").get("signature_rejects_replay", 0)
    mark = station.mark()
    station.write(captured)
    fresh_station = client(udp_url(d.port("gcs")), 254, 190)
    sign(fresh_station, KEY, link_id=3)
    assert arm_ack(fresh_station) is not None, "a fresh signed request is answered"
    pump([station], 0.2)
    assert not [r for r in station.received[mark:] if is_ack(M.MAV_CMD_REQUEST_MESSAGE)(r)]
    assert d.stats("gcs")["signature_rejects_replay"] == replays_before + 1


def test_a_signed_frame_ten_years_ahead_is_refused_and_locks_nobody_out_even_after_a_restart(daemon, client, tmp_path):
    d = signed_daemon(daemon, tmp_path)
    ahead = client(udp_url(d.port("gcs")), 240, 190)
    sign(ahead, KEY, timestamp=now_units() + TEN_YEARS_UNITS)
    station = client(udp_url(d.port("gcs")))
    sign(station, KEY, link_id=1)
    mark = ahead.mark()
    ahead.command_long(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    # the station's request reaches the same socket after it: its answer ends the window
    assert arm_ack(station) is not None, "a station with a true clock is answered"
    pump([ahead], 0.05)
    assert ahead.received[mark:] == [], "the frame from the future got nothing"
    assert d.stats("gcs")["signature_rejects_future"] == 1
    d.stop()
    again = signed_daemon(daemon, tmp_path)
    later = client(udp_url(again.port("gcs")), 254, 190)
    sign(later, KEY, link_id=2)
    assert arm_ack(later) is not None, "the saved timestamp was never raised by the future frame"


# --- no amplification ----------------------------------------------------------------------

def test_garbage_and_rejected_frames_get_nothing_back_while_a_station_is_served(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    station = client(udp_url(d.port("gcs")))
    station.heartbeat()
    assert served(station)
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stranger.bind(("127.0.0.1", 0))
    stranger.settimeout(0.2)
    try:
        bad_crc = bytearray(packed(M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)))
        bad_crc[-1] ^= 0xFF
        for payload in (b"\x00", b"\xfd", bytes(bad_crc), bad_crc[:7], b"\xfe\x09" + bytes(20)):
            stranger.sendto(payload, ("127.0.0.1", d.port("gcs")))
        assert served(station)
        got = []
        try:
            got.append(stranger.recv(65536))
        except TimeoutError:
            pass
        assert got == [], "garbage earns its sender nothing"
        stranger.sendto(packed(M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3), 250, 190), ("127.0.0.1", d.port("gcs")))
        stranger.settimeout(2.0)
        assert stranger.recv(65536), "a good frame makes the sender a peer"
    finally:
        stranger.close()


def test_one_byte_datagrams_from_6000_ports_do_not_starve_a_station(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    station = client(udp_url(d.port("gcs")))
    station.heartbeat()
    assert served(station)
    port = d.port("gcs")
    sent = []

    def flood() -> None:
        for _ in range(6000):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.sendto(b"\x00", ("127.0.0.1", port))
            s.close()
            sent.append(1)

    flooder = threading.Thread(target=flood)
    flooder.start()
    latencies = []
    try:
        while flooder.is_alive() or len(latencies) < 20:
            mark = station.mark()
            t0 = time.monotonic()
            station.send(M.MAVLink_param_request_read_message(1, 1, b"SYSID_THISMAV", -1))
            reply = wait_for(station, lambda r: r.type == "PARAM_VALUE", timeout=2.0, since=mark)
            assert reply is not None, "every request of the station is answered during the flood"
            latencies.append(time.monotonic() - t0)
    finally:
        flooder.join()
    latencies.sort()
    assert len(sent) == 6000
    assert latencies[int(len(latencies) * 0.99) - 1] < 0.25
    stats = d.stats("gcs")
    assert stats["peers"] == 1 and stats["parse_errors"] >= 1


def test_at_most_max_peers_are_served_and_the_silent_one_is_replaced(daemon, client):
    d = daemon({"channels": [udp_channel("gcs", max_peers=2)]})
    first, second, third = (client(udp_url(d.port("gcs")), 250 + i, 190) for i in range(3))
    first.heartbeat()
    assert served(first)
    second.heartbeat()
    assert served(second)
    second.heartbeat()  # second is heard after first: first is the silent one
    pump([first, second], 0.1)
    third.heartbeat()
    assert served(third)
    stats = d.stats("gcs")
    assert stats["peers"] == 2 and stats["peers_replaced"] == 1
    marks = [c.mark() for c in (first, second, third)]
    end = time.monotonic() + 3.0  # until each served station has its share of the streams
    while time.monotonic() < end and min(len(vehicle_frames(c, m)) for c, m in zip((second, third), marks[1:])) < 10:
        pump([first, second, third], 0.05)
    got = [vehicle_frames(c, m) for c, m in zip((first, second, third), marks)]
    assert got[1] and got[2], "the two served stations keep receiving"
    assert not got[0], "the silent one was dropped"


# --- one version per peer ------------------------------------------------------------------

def test_mavlink1_and_mavlink2_stations_on_one_channel_each_keep_their_version(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    new = client(udp_url(d.port("gcs")), 254, 190, version=2)
    old = client(udp_url(d.port("gcs")), 255, 190, version=1)
    new.heartbeat()
    old.heartbeat()
    mark_new, mark_old = new.mark(), old.mark()
    for _ in range(6):  # both keep talking, in turns
        old.heartbeat()
        pump([new, old], 0.15)
        new.heartbeat()
        pump([new, old], 0.15)
    to_new, to_old = vehicle_frames(new, mark_new), vehicle_frames(old, mark_old)
    assert len(to_new) > 10 and {f[0] for f in to_new} == {0xFD}, "MAVLink2 station: MAVLink2 only"
    assert len(to_old) > 10 and {f[0] for f in to_old} == {0xFE}, "MAVLink1 station: MAVLink1 only"


def test_radio_status_does_not_set_a_peers_version(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    station = client(udp_url(d.port("gcs")), 255, 190, version=1)
    station.heartbeat()
    assert served(station)
    station.write(packed(M.MAVLink_radio_status_message(200, 200, 100, 0, 0, 0, 0), 51, 68, version=2))
    mark = station.mark()
    assert served(station)
    assert {f[0] for f in vehicle_frames(station, mark)} == {0xFE}


# --- error boundaries ----------------------------------------------------------------------

def test_a_raising_producer_is_counted_and_everything_else_keeps_streaming(daemon, client, tmp_path):
    from gcsd.vehicle import telemetry

    def broken(view, channel, now):
        raise RuntimeError("deliberately broken producer")

    producers = {**telemetry.producers(), M.MAVLINK_MSG_ID_SYS_STATUS: broken}
    d = daemon({"channels": [udp_channel("gcs")]}, producers=producers)
    station = client(udp_url(d.port("gcs")))
    station.heartbeat()
    wanted = {"HEARTBEAT", "ATTITUDE", "GLOBAL_POSITION_INT", "VFR_HUD"}
    end = time.monotonic() + 5.0  # until the others streamed and SYS_STATUS was due (and failed) twice
    while time.monotonic() < end and not (wanted <= {r.type for r in station.received if r.src == VEHICLE}
                                          and d.status()["errors"].get("producer:SYS_STATUS", 0) >= 2):
        pump([station], 0.1)
    kinds = {r.type for r in station.received if r.src == VEHICLE}
    assert wanted <= kinds
    assert "SYS_STATUS" not in kinds
    assert d.status()["errors"]["producer:SYS_STATUS"] >= 2
    conf = tmp_path / "same.yaml"
    conf.write_text(f"state_dir: {d.config.state_dir}\n")
    shown = subprocess.run([sys.executable, "-m", "gcsd", "status", "-c", str(conf), "--json"], check=False,
                           capture_output=True, text=True, timeout=20)
    assert shown.returncode == 0, shown.stderr
    assert json.loads(shown.stdout)["errors"]["producer:SYS_STATUS"] >= 2, "gcsd status shows it"
    table = subprocess.run([sys.executable, "-m", "gcsd", "status", "-c", str(conf)], check=False,
                           capture_output=True, text=True, timeout=20)
    assert "producer:SYS_STATUS" in table.stdout


class _RaisingBackend:
    """An embedding program whose update raises every time, and counts its calls."""

    def __init__(self) -> None:
        self.calls = 0

    def update(self, state, setpoint, limits, dt_s) -> None:
        self.calls += 1
        state.landed = Landed.ON_GROUND
        raise ValueError("the robot's driver fell over")


def test_a_raising_backend_is_counted_and_the_vehicle_keeps_talking(daemon, client):
    backend = _RaisingBackend()
    d = daemon({"channels": [udp_channel("gcs")]}, backend=lambda index: backend)
    station = client(udp_url(d.port("gcs")))
    station.heartbeat()
    assert served(station)
    mark = station.mark()
    station.send(M.MAVLink_param_request_read_message(1, 1, b"SYSID_THISMAV", -1))
    assert wait_for(station, lambda r: r.type == "PARAM_VALUE", since=mark) is not None
    assert _until(lambda: backend.calls >= 10), "the autopilot keeps calling the backend"
    counted = d.status()["errors"]["backend"]
    assert 10 <= counted <= backend.calls


class _CountingBackend:
    def __init__(self) -> None:
        self.calls = 0

    def update(self, state, setpoint, limits, dt_s) -> None:
        self.calls += 1


async def test_the_simulation_steps_with_no_link_up(tmp_path):
    closed = socket.socket()
    closed.bind(("127.0.0.1", 0))
    port = closed.getsockname()[1]
    closed.close()  # nothing listens there: the only link never comes up
    config = parse_config(yaml.safe_dump({
        "state_dir": str(tmp_path / "st"),
        "channels": [{"name": "fc", "type": "tcp-client", "address": f"127.0.0.1:{port}"}],
    }), "test.yaml")
    backend = _CountingBackend()
    gcs = Daemon(config, backend=lambda index: backend)
    stop = asyncio.Event()
    runner = asyncio.create_task(gcs.run(stop))
    try:
        deadline = time.monotonic() + 5.0
        while backend.calls < 20 and time.monotonic() < deadline and not runner.done():
            await asyncio.sleep(0.05)
        assert 0 not in gcs.opened, "the fc link never came up"  # (the API's http channel is open)
        assert backend.calls >= 20, "the autopilot and its backend tick whether or not a link is up"
    finally:
        stop.set()
        await asyncio.wait_for(runner, 5.0)


def _until(condition, timeout_s: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


# --- startup -------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", [socket.SOCK_DGRAM, socket.SOCK_STREAM])
def test_a_server_port_already_taken_is_exit_1_with_one_line(tmp_path, kind):
    holder = socket.socket(socket.AF_INET, kind)
    holder.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as QGroundControl binds 14550
    holder.bind(("127.0.0.1", 0))
    if kind == socket.SOCK_STREAM:
        holder.listen()
    port = holder.getsockname()[1]
    channel_type = "udp-server" if kind == socket.SOCK_DGRAM else "tcp-server"
    conf = tmp_path / "taken.yaml"
    conf.write_text(f"state_dir: {tmp_path / 'st'}\nchannels:\n  - name: gcs\n    type: {channel_type}\n"
                    f"    address: 127.0.0.1:{port}\n")
    try:
        proc = subprocess.run([sys.executable, "-m", "gcsd", "run", "-c", str(conf)], check=False, capture_output=True,
                              text=True, timeout=20)
    finally:
        holder.close()
    out = proc.stdout + proc.stderr
    assert proc.returncode == 1
    assert "Traceback" not in out
    failures = [line for line in out.splitlines() if "daemon_failed" in line]
    assert len(failures) == 1 and f"127.0.0.1:{port}" in failures[0]
