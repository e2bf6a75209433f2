"""Missions, fence and rally with real clients, against gcsd as a subprocess.

- MAVSDK (`mission_raw`; `geofence` to clear a fence; `mavlink_direct` to clear rally points,
  which MAVSDK has no call for) uploads, downloads and clears each plan type and gets back
  exactly what it sent.
- MAVProxy (`wp`, `fence`, `rally` modules, driven by stdin lines) loads QGC WPL files, lists and
  saves them back: the saved file equals the loaded one; `wp clear` empties the mission.
- SIGKILL while an upload is in progress leaves the previous plan in the state directory.
- A 500-item mission through a proxy losing 20 % of the datagrams each way, with MAVProxy and
  MAVSDK (minutes each, so only with GCSD_LONG_TESTS=1; see each test for what its client does
  about loss).
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import sys
import time
from contextlib import asynccontextmanager

import pytest

pytest.importorskip("mavsdk.asyncio", reason="mavsdk is a test extra: pip install -e .[test]")

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.geofence import GeofenceAsync
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
from mavsdk.asyncio.plugins.mission_raw import MissionItem, MissionRawAsync, MissionRawError
from mavsdk.plugins.mavlink_direct import MavlinkMessage
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission import MissionItem as Item
from integration.helpers import Client, udp_url
from integration.mission_client import LossyProxy, MissionClient

from .conftest import DEFAULT_HOME, REPO_ROOT
from .conftest import mavproxy_script as _mavproxy_script

DISCOVERY_WAIT_S = 5.0
LONG_REASON = "takes minutes: set GCSD_LONG_TESTS=1"
HOME_X, HOME_Y = round(DEFAULT_HOME.lat_deg * 1e7), round(DEFAULT_HOME.lon_deg * 1e7)
LAT, LON = -353630000, 1491650000


# --- MAVSDK ----------------------------------------------------------------------------------------


@asynccontextmanager
async def ground_station(port: int):
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        await mavsdk.add_any_connection(f"udpout://127.0.0.1:{port}")
        system = await mavsdk.first_autopilot(timeout_s=DISCOVERY_WAIT_S)
        assert system is not None, f"MAVSDK found no autopilot within {DISCOVERY_WAIT_S} s"
        yield system
    finally:
        mavsdk.destroy()


def mavsdk_mission(n: int = 6) -> list[MissionItem]:
    """Home as item 0 (current = 1: MAVSDK wants exactly one current item), then a small plan."""
    wp, takeoff, jump = M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_DO_JUMP
    items = [MissionItem(0, 0, wp, 1, 1, 0, 0, 0, 0, HOME_X, HOME_Y, DEFAULT_HOME.alt_m, 0),
             MissionItem(1, 6, takeoff, 0, 1, 0, 0, 0, 0, 0, 0, 20.0, 0)]
    for i in range(2, n - 1):
        items.append(MissionItem(i, 6, wp, 0, 1, 0.0, 2.5, 0, 0, LAT + 1111 * i, LON - 777 * i, 30.0 + i, 0))
    items.append(MissionItem(n - 1, 2, jump, 0, 1, 2.0, 3.0, 0, 0, 0, 0, 0.0, 0))
    return items


def mavsdk_fence() -> list[MissionItem]:
    t = M.MAV_MISSION_TYPE_FENCE
    vertex, circle = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
    items = [MissionItem(0, 5, M.MAV_CMD_NAV_FENCE_RETURN_POINT, 1, 1, 0, 0, 0, 0, LAT, LON, 0.0, t)]
    for i, (dx, dy) in enumerate(((-5000, -5000), (-5000, 5000), (5000, 5000), (5000, -5000)), start=1):
        items.append(MissionItem(i, 5, vertex, 0, 1, 4.0, 0, 0, 0, LAT + dx, LON + dy, 0.0, t))
    items.append(MissionItem(5, 5, circle, 0, 1, 30.0, 0, 0, 0, LAT, LON + 900, 0.0, t))
    return items


def mavsdk_rally() -> list[MissionItem]:
    t = M.MAV_MISSION_TYPE_RALLY
    return [MissionItem(i, 6, M.MAV_CMD_NAV_RALLY_POINT, int(i == 0), 1, 0, 0, 0, 0,
                        LAT + 400 * i, LON - 300 * i, 45.0 + i, t) for i in range(3)]


def fields(items) -> list[dict]:
    return [vars(i) for i in items]


async def clear_rally(system) -> None:
    direct = MavlinkDirectAsync(system)
    try:
        await direct.send_message(
            MavlinkMessage(
                "MISSION_CLEAR_ALL",
                255,
                190,
                1,
                1,
                json.dumps(
                    {"target_system": 1, "target_component": 1, "mission_type": M.MAV_MISSION_TYPE_RALLY}
                ),
            )
        )
    finally:
        direct.destroy()


@pytest.mark.interop
async def test_mavsdk_uploads_downloads_and_clears_a_mission(gcsd_daemon):
    daemon = gcsd_daemon()
    async with ground_station(daemon.port("gcs")) as system:
        mission = MissionRawAsync(system)
        try:
            sent = mavsdk_mission()
            await mission.upload_mission(sent)
            assert fields(await mission.download_mission()) == fields(sent)
            # For ArduPilot, MAVSDK clears by uploading one placeholder item 0, which is home:
            # what is left is home alone, as on a vehicle that never had a mission.
            await mission.clear_mission()
            assert fields(await mission.download_mission()) == fields(sent[:1])
        finally:
            mission.destroy()


@pytest.mark.interop
async def test_mavsdk_uploads_downloads_and_clears_a_fence(gcsd_daemon):
    daemon = gcsd_daemon()
    async with ground_station(daemon.port("gcs")) as system:
        mission, geofence = MissionRawAsync(system), GeofenceAsync(system)
        try:
            sent = mavsdk_fence()
            await mission.upload_geofence(sent)
            assert fields(await mission.download_geofence()) == fields(sent)
            await geofence.clear_geofence()
            assert await mission.download_geofence() == []
        finally:
            geofence.destroy()
            mission.destroy()


@pytest.mark.interop
async def test_mavsdk_uploads_downloads_and_clears_rally_points(gcsd_daemon):
    daemon = gcsd_daemon()
    async with ground_station(daemon.port("gcs")) as system:
        mission = MissionRawAsync(system)
        try:
            sent = mavsdk_rally()
            await mission.upload_rally_points(sent)
            assert fields(await mission.download_rallypoints()) == fields(sent)
            await clear_rally(system)
            for _ in range(20):  # the clear is fire-and-forget through mavlink_direct
                if await mission.download_rallypoints() == []:
                    break
                await asyncio.sleep(0.1)
            assert await mission.download_rallypoints() == []
        finally:
            mission.destroy()


@pytest.mark.interop
async def test_mavsdk_sees_an_invalid_fence_refused_and_the_old_one_kept(gcsd_daemon):
    daemon = gcsd_daemon()
    async with ground_station(daemon.port("gcs")) as system:
        mission = MissionRawAsync(system)
        try:
            good = mavsdk_fence()
            await mission.upload_geofence(good)
            bad = mavsdk_fence()[:3]  # a polygon declaring 4 vertices with only 2
            with pytest.raises(MissionRawError):
                await mission.upload_geofence(bad)
            assert fields(await mission.download_geofence()) == fields(good)
        finally:
            mission.destroy()


# --- MAVProxy --------------------------------------------------------------------------------------


@pytest.fixture
def mavproxy(spawn, tmp_path):
    """mavproxy(port) -> a headless MAVProxy with its wp, fence and rally modules, in tmp_path."""
    pytest.importorskip("MAVProxy", reason="MAVProxy is a test extra: pip install -e .[test]")
    started = []

    def start(port: int):
        argv = [sys.executable, _mavproxy_script(), f"--master=udpout:127.0.0.1:{port}", "--no-state",
                "--default-modules=wp,fence,rally"]
        process = spawn(argv, name="mavproxy", cwd=tmp_path, env_overrides={"HOME": str(tmp_path)})
        started.append(process)
        expect(process, r"Detected vehicle 1:1", 10.0, 0, "the vehicle")
        return process

    yield start
    for process in started:
        process.stop(5.0, end_of_input_first=True)


def expect(process, pattern: str, timeout_s: float, since: int, what: str):
    found = process.output.wait_for(pattern, timeout_s, since=since)
    if found is None:
        pytest.fail(
            f"MAVProxy did not print {what} (/{pattern}/) within {timeout_s} s\n{process.describe()}",
            pytrace=False,
        )
    return found


def command(process, line: str, pattern: str, timeout_s: float, what: str):
    since = len(process.output)
    process.send_line(line)
    return expect(process, pattern, timeout_s, since, what)


def wpl(lines: list[tuple]) -> str:
    """A QGC WPL 110 file as MAVProxy writes it (six decimals)."""
    out = ["QGC WPL 110"]
    for seq, (cur, frame, cmd, p1, p2, p3, p4, x, y, z, auto) in enumerate(lines):
        out.append(f"{int(seq)}\t{int(cur)}\t{int(frame)}\t{int(cmd)}\t{p1:f}\t{p2:f}\t{p3:f}\t{p4:f}\t"
                   f"{x:f}\t{y:f}\t{z:f}\t{int(auto)}")
    return "\n".join(out) + "\n"


MISSION_FILE = wpl(
    [
        (1, 0, 16, 0, 0, 0, 0, DEFAULT_HOME.lat_deg, DEFAULT_HOME.lon_deg, DEFAULT_HOME.alt_m, 1),
        (0, 3, 22, 0, 0, 0, 0, 0, 0, 20, 1),
        (0, 3, 16, 0, 2, 0, 0, -35.361, 149.163, 30, 1),
        (0, 3, 16, 0, 0, 0, 0, -35.3605, 149.1645, 35.5, 1),
        (0, 2, 177, 2, 1, 0, 0, 0, 0, 0, 1),
        (0, 2, 20, 0, 0, 0, 0, 0, 0, 0, 1),
    ]
)
FENCE_FILE = wpl(
    [(0, 0, 5000, 0, 0, 0, 0, -35.3632, 149.1652, 0, 1)]
    + [
        (0, 0, 5001, 4, 0, 0, 0, -35.3632 + dx, 149.1652 + dy, 0, 1)
        for dx, dy in ((-0.001, -0.001), (-0.001, 0.001), (0.001, 0.001), (0.001, -0.001))
    ]
    + [(0, 0, 5004, 50, 0, 0, 0, -35.3635, 149.1655, 0, 1)]
)
RALLY_FILE = wpl(
    [(0, 3, 5100, 0, 0, 0, 0, -35.362 + 0.001 * i, 149.164 - 0.001 * i, 40 + i, 1) for i in range(3)]
)


@pytest.mark.interop
@pytest.mark.parametrize(
    ("module", "text", "noun", "type_name"),
    [
        ("wp", MISSION_FILE, "waypoints", "MISSION"),
        ("fence", FENCE_FILE, "fence items", "FENCE"),
        ("rally", RALLY_FILE, "rally items", "RALLY"),
    ],
)
def test_mavproxy_loads_lists_and_saves_back_the_same_file(
    gcsd_daemon, mavproxy, tmp_path, module, text, noun, type_name
):
    daemon = gcsd_daemon()
    process = mavproxy(daemon.port("gcs"))
    source, saved = tmp_path / f"{module}-in.txt", tmp_path / f"{module}-out.txt"
    source.write_text(text)
    count = len(text.splitlines()) - 1
    command(
        process,
        f"{module} load {source}",
        rf"Got MISSION_ACK: TYPE_{type_name}: ACCEPTED",
        10.0,
        f"the {module} upload accepted",
    )
    command(process, f"{module} list", rf"Requesting {count} {noun}", 5.0, f"the {module} count")
    command(
        process,
        f"{module} save {saved}",
        rf"Saved {count} {noun} to {re.escape(str(saved))}",
        10.0,
        f"the {module} download saved",
    )
    assert saved.read_text() == text, daemon.describe()


@pytest.mark.interop
def test_mavproxy_wp_clear_empties_the_mission(gcsd_daemon, mavproxy, tmp_path):
    daemon = gcsd_daemon()
    process = mavproxy(daemon.port("gcs"))
    source = tmp_path / "mission.txt"
    source.write_text(MISSION_FILE)
    command(
        process, f"wp load {source}", r"Got MISSION_ACK: TYPE_MISSION: ACCEPTED", 10.0, "the upload accepted"
    )
    command(process, "wp clear", r"Got MISSION_ACK: TYPE_MISSION: ACCEPTED", 5.0, "the clear accepted")
    command(process, "wp list", r"Requesting 0 waypoints", 5.0, "an empty mission")
    command(process, "fence list", r"Requesting 0 fence items", 5.0, "an empty fence")


# --- crash safety ----------------------------------------------------------------------------------


def _plan(n: int, salt: int) -> list[Item]:
    home = Item(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 1, 1, 0, 0, 0, 0,
                HOME_X, HOME_Y, DEFAULT_HOME.alt_m)
    return [home] + [Item(M.MAV_CMD_NAV_WAYPOINT, 6, 0, 1, 0, 0, 0, 0, LAT + salt + i, LON + i, 20.0 + i)
                     for i in range(1, n)]


@pytest.mark.interop
def test_sigkill_during_an_upload_leaves_the_previous_plan(gcsd_daemon, spawn, tmp_path):
    state = tmp_path / "victim-state"
    config = tmp_path / "victim.yaml"
    config.write_text(json.dumps({
        "state_dir": str(state), "log": {"format": "json"},
        "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}],
    }))
    pythonpath = [os.environ.get("PYTHONPATH"), str(REPO_ROOT / "src")]
    env = {"PYTHONPATH": os.pathsep.join(filter(None, pythonpath))}
    victim = spawn([sys.executable, "-m", "gcsd", "run", "-c", str(config)], name="victim", env_overrides=env)
    found = victim.output.wait_for(r'"channel_opened"', 10.0)
    assert found is not None, victim.describe()
    port = int(json.loads(victim.output.lines(found[0])[0][1])["address"].rpartition(":")[2])
    c = Client(udp_url(port), 255, 190)
    try:
        c.heartbeat()
        mc = MissionClient(c)
        old, new = _plan(40, 0), _plan(60, 5000)
        assert mc.upload(old, 0) == M.MAV_MISSION_ACCEPTED
        saved_before = (state / "mission.waypoints").read_bytes()
        # half of a new upload, then the process dies
        c.send(M.MAVLink_mission_count_message(1, 1, len(new), 0))
        for seq in range(30):
            deadline = time.monotonic() + 2.0
            while not any(r.type == "MISSION_REQUEST" and r.msg.seq == seq for r in c.received):
                assert time.monotonic() < deadline, f"no request for item {seq}"
                c.read_available()
                time.sleep(0.001)
            it = new[seq]
            c.send(M.MAVLink_mission_item_int_message(1, 1, seq, it.frame, it.command, it.current,
                                                      it.autocontinue, it.param1, it.param2, it.param3,
                                                      it.param4, it.x, it.y, it.z, 0))
        victim.popen.send_signal(signal.SIGKILL)
        victim.popen.wait(5.0)
    finally:
        c.close()
    assert (state / "mission.waypoints").read_bytes() == saved_before

    daemon = gcsd_daemon({"state_dir": str(state)})
    c2 = Client(udp_url(daemon.port("gcs")), 255, 190)
    try:
        c2.heartbeat()
        assert MissionClient(c2).download(0) == old
    finally:
        c2.close()


# --- lossy links -----------------------------------------------------------------------------------


def retried(process, line: str, pattern: str, attempt_s: float, attempts: int, what: str,
            failed: str | None = None) -> int:
    """Send a command again until its line appears (or at once when `failed` appears), as a user
    at the console would; returns the attempt that worked."""
    either = pattern if failed is None else f"(?:{pattern})|(?:{failed})"
    for attempt in range(1, attempts + 1):
        since = len(process.output)
        process.send_line(line)
        found = process.output.wait_for(either, attempt_s, since=since)
        if found is not None and re.search(pattern, found[2][0]):
            return attempt
    pytest.fail(f"MAVProxy did not print {what} after {attempts} x `{line}`\n{process.describe()}",
                pytrace=False)


@pytest.mark.interop
@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("GCSD_LONG_TESTS"), reason=LONG_REASON)
def test_mavproxy_round_trips_500_items_through_20_percent_loss(gcsd_daemon, mavproxy, tmp_path):
    """MAVProxy answers each MISSION_REQUEST; gcsd re-requests what is lost after its adaptive
    timeout (the default configuration: tens of ms on loopback, see gcsd.vehicle.mission.rtt). MAVProxy stops answering once it has sent the last item, so a lost last
    item (or a lost ACK) fails that upload: the command is repeated, as its user would. Downloading,
    MAVProxy asks 5 items ahead and asks again only after 2 s, so every lost item costs it 2 s,
    and a lost MISSION_REQUEST_LIST or MISSION_COUNT is never asked again: `wp save` is repeated
    when no "Requesting" line comes."""
    daemon = gcsd_daemon()
    proxy = LossyProxy(daemon.port("gcs"), loss=0.2, seed=500)
    try:
        process = mavproxy(proxy.port)
        lines = [(1, 0, 16, 0, 0, 0, 0, DEFAULT_HOME.lat_deg, DEFAULT_HOME.lon_deg, DEFAULT_HOME.alt_m, 1)]
        lines += [(0, 3, 16, 0, 0, 0, 0, -35.36 + 0.0001 * i, 149.16 + 0.0001 * (i % 17), 10 + i % 90, 1)
                  for i in range(1, 500)]
        text = wpl(lines)
        source, saved = tmp_path / "big.txt", tmp_path / "big-out.txt"
        source.write_text(text)
        started = time.monotonic()
        uploads = retried(process, f"wp load {source}", r"Got MISSION_ACK: TYPE_MISSION: ACCEPTED", 60.0, 8,
                          "the upload accepted", failed=r"Mission upload timeout")
        uploaded = time.monotonic()
        lists = retried(process, f"wp save {saved}", r"Requesting 500 waypoints", 3.0, 20, "the count")
        expect(process, rf"Saved 500 waypoints to {re.escape(str(saved))}", 900.0, 0, "the download saved")
        print(f"MAVProxy, 500 items, 20 % loss each way: upload {uploaded - started:.1f} s "
              f"({uploads} attempts), "
              f"download {time.monotonic() - uploaded:.1f} s ({lists} list requests); "
              f"proxy dropped {proxy.dropped}")
        assert saved.read_text() == text
    finally:
        proxy.close()


@pytest.mark.interop
@pytest.mark.slow
@pytest.mark.skipif(not os.environ.get("GCSD_LONG_TESTS"), reason=LONG_REASON)
async def test_mavsdk_round_trips_500_items_through_20_percent_loss(gcsd_daemon):
    """MAVSDK gives each item 5 tries 0.5 s apart and then abandons the whole transfer. Uploading,
    gcsd re-requests a lost item after its adaptive timeout (default configuration); downloading, gcsd sends
    an item asked for again twice. A whole transfer can still fail now and then on 20 % loss each
    way, so, as a MAVSDK application would, this retries a failed upload or download (up to 8
    times); gcsd keeps the old plan until an upload completes, so a failed attempt leaves nothing
    half-written. About 2-3 minutes when the first attempts succeed."""
    daemon = gcsd_daemon()
    proxy = LossyProxy(daemon.port("gcs"), loss=0.2, seed=501)
    attempts = {"upload": 0, "download": 0}
    try:
        async with ground_station(proxy.port) as system:
            mission = MissionRawAsync(system)
            try:
                sent = mavsdk_mission(6)[:1] + [
                    MissionItem(
                        i,
                        6,
                        M.MAV_CMD_NAV_WAYPOINT,
                        0,
                        1,
                        0,
                        0,
                        0,
                        0,
                        LAT + 97 * i,
                        LON - 53 * i,
                        10.0 + i % 90,
                        0,
                    )
                    for i in range(1, 500)
                ]
                got = None
                started = time.monotonic()
                for _ in range(8):
                    attempts["upload"] += 1
                    try:
                        await mission.upload_mission(sent)
                        break
                    except MissionRawError:
                        continue
                uploaded = time.monotonic()
                for _ in range(8):
                    attempts["download"] += 1
                    try:
                        got = await mission.download_mission()
                        break
                    except MissionRawError:
                        continue
                print(
                    f"MAVSDK, 500 items, 20 % loss each way: upload {uploaded - started:.1f} s, download "
                    f"{time.monotonic() - uploaded:.1f} s, attempts {attempts}; proxy dropped {proxy.dropped}"
                )
                assert got is not None, f"download failed {attempts['download']} times"
                assert fields(got) == fields(sent)
            finally:
                mission.destroy()
    finally:
        proxy.close()
