"""Real clients through a link that loses 20 % of the datagrams in each direction, with gcsd's
default configuration (only the port is the test's): the transfers the vehicle drives must get
through on re-requests timed by the measured round trip (gcsd.vehicle.mission.rtt), not ArduPilot's fixed 1 s.

- MAVSDK `mission_raw.upload_mission`: MAVSDK never resends an item on its own; it answers each
  MISSION_REQUEST and abandons the upload after 5 sends of one item or 5 of its 0.5 s timeouts.
  At 20 % loss each way one item in 3 000 is lost 5 times on its way up, whatever the vehicle
  does, so a MAVSDK application retries a failed upload (gcsd keeps the old plan until one
  completes); the test allows that and reports the attempts.
- MAVProxy `wp load`: answers each request, but stops answering once it has sent the last item
  and never resends MISSION_COUNT, so a lost count, last item or final ACK fails the attempt: the
  test repeats the command, as its user would.
- a full parameter download: MAVSDK `param.get_all_params()` (PARAM_REQUEST_LIST, then what is
  missing by index) and MAVProxy `param fetch` (@PARAM/param.pck over FTP, its default).
The uploaded plans are then read back straight from the daemon (no loss) and compared.

Sizes: 100 items in CI; 500 with GCSD_LONG_TESTS=1 (bench/lossy.py measures the same paths at
0 to 30 % loss).
"""

from __future__ import annotations

import asyncio
import os
import re
import sys
import time

import pytest

pytest.importorskip("mavsdk.asyncio", reason="mavsdk is a test extra: pip install -e .[test]")

from mavsdk.asyncio.plugins.mission_raw import MissionItem, MissionRawAsync, MissionRawError
from mavsdk.asyncio.plugins.param import ParamAsync
from pymavlink.dialects.v20 import ardupilotmega as M

from integration.helpers import Client, udp_url
from integration.mission_client import LossyProxy, MissionClient

from .conftest import DEFAULT_HOME
from .conftest import mavproxy_script as _mavproxy_script
from .test_mission_interop import ground_station  # MAVSDK as a ground station on udpout

ITEMS = 500 if os.environ.get("GCSD_LONG_TESTS") else 100
LOSS = 0.2
HOME_X, HOME_Y = round(DEFAULT_HOME.lat_deg * 1e7), round(DEFAULT_HOME.lon_deg * 1e7)
LAT, LON = -353630000, 1491650000


def read_back(port: int, mission_type: int = 0):
    c = Client(udp_url(port), 255, 190)
    try:
        c.heartbeat()
        return MissionClient(c).download(mission_type)
    finally:
        c.close()


@pytest.mark.interop
async def test_mavsdk_uploads_a_mission_through_20_percent_loss_each_way(gcsd_daemon):
    daemon = gcsd_daemon()
    proxy = LossyProxy(daemon.port("gcs"), loss=LOSS, seed=1301)
    items = [MissionItem(0, 0, M.MAV_CMD_NAV_WAYPOINT, 1, 1, 0, 0, 0, 0, HOME_X, HOME_Y, DEFAULT_HOME.alt_m, 0)]
    items += [MissionItem(i, 6, M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0, LAT + 97 * i, LON - 53 * i,
                          10.0 + i % 90, 0) for i in range(1, ITEMS)]
    attempts, started = 0, time.monotonic()
    try:
        async with ground_station(proxy.port) as system:
            mission = MissionRawAsync(system)
            try:
                for attempts in range(1, 9):
                    try:
                        await mission.upload_mission(items)
                        break
                    except MissionRawError as exc:
                        print(f"MAVSDK upload attempt {attempts} failed: {str(exc)[:40]}")
                else:
                    pytest.fail(f"8 uploads of {ITEMS} items failed; proxy dropped {proxy.dropped}")
            finally:
                mission.destroy()
        took = time.monotonic() - started
    finally:
        proxy.close()
    print(f"MAVSDK upload, {ITEMS} items, 20 % loss each way: {took:.1f} s, {attempts} attempt(s), "
          f"proxy dropped {proxy.dropped}")
    assert proxy.dropped["up"] > ITEMS // 10 and proxy.dropped["down"] > ITEMS // 10
    got = read_back(daemon.port("gcs"))
    assert [(i.x, i.y, i.z) for i in got[1:]] == [(i.x, i.y, pytest.approx(i.z)) for i in items[1:]]


@pytest.mark.interop
def test_mavproxy_wp_load_gets_a_mission_through_20_percent_loss_each_way(gcsd_daemon, spawn, tmp_path):
    pytest.importorskip("MAVProxy", reason="MAVProxy is a test extra: pip install -e .[test]")
    daemon = gcsd_daemon()
    proxy = LossyProxy(daemon.port("gcs"), loss=LOSS, seed=1302)
    lines = ["QGC WPL 110",
             f"0\t1\t0\t16\t0\t0\t0\t0\t{DEFAULT_HOME.lat_deg:.8f}\t{DEFAULT_HOME.lon_deg:.8f}\t{DEFAULT_HOME.alt_m:.6f}\t1"]
    lines += [f"{i}\t0\t3\t16\t0\t0\t0\t0\t{-35.36 + 0.0001 * i:.8f}\t{149.16 + 0.0001 * (i % 17):.8f}\t"
              f"{10 + i % 90:.6f}\t1" for i in range(1, ITEMS)]
    source = tmp_path / "plan.txt"
    source.write_text("\n".join(lines) + "\n")
    argv = [sys.executable, _mavproxy_script(), f"--master=udpout:127.0.0.1:{proxy.port}", "--no-state",
            "--default-modules=wp"]
    process = spawn(argv, name="mavproxy", cwd=tmp_path, env_overrides={"HOME": str(tmp_path)})
    try:
        assert process.output.wait_for(r"Detected vehicle 1:1", 20.0) is not None, process.describe()
        started = time.monotonic()
        accepted = r"Got MISSION_ACK: TYPE_MISSION: ACCEPTED"
        for attempt in range(1, 13):
            since = len(process.output)
            process.send_line(f"wp load {source}")
            # As a user at the console: the upload worked when the ACK is printed. MAVProxy prints
            # "Sent all N" when it has answered the last request; no ACK 2 s after that (the last
            # item or the ACK was lost), or no progress at all (the count was lost): repeat.
            found = process.output.wait_for(f"(?:{accepted})|(?:Sent all {ITEMS} )", 3.0 + ITEMS * 0.1,
                                            since=since)
            if found is not None and not re.search(accepted, found[2][0]):
                found = process.output.wait_for(accepted, 2.0, since=since)
            if found is not None and re.search(accepted, found[2][0]):
                break
        else:
            pytest.fail(f"12 `wp load` attempts failed\n{process.describe()}\n{daemon.describe()}", pytrace=False)
        took = time.monotonic() - started
    finally:
        process.stop(5.0, end_of_input_first=True)
        proxy.close()
    print(f"MAVProxy wp load, {ITEMS} items, 20 % loss each way: {took:.1f} s, {attempt} attempt(s), "
          f"proxy dropped {proxy.dropped}")
    got = read_back(daemon.port("gcs"))
    assert len(got) == ITEMS
    wrong = [i for i, item in enumerate(got[1:], 1) if abs(item.x - (-35.36 + 0.0001 * i) * 1e7) > 1]
    assert wrong == [], f"items {wrong[:10]} differ from the file"


@pytest.mark.interop
async def test_mavsdk_downloads_every_parameter_through_20_percent_loss_each_way(gcsd_daemon):
    daemon = gcsd_daemon()
    expected = _param_count(daemon.port("gcs"))
    proxy = LossyProxy(daemon.port("gcs"), loss=LOSS, seed=1303)
    try:
        async with ground_station(proxy.port) as system:
            param = ParamAsync(system)
            try:
                started = time.monotonic()
                every = await asyncio.wait_for(param.get_all_params(), 120.0)
                took = time.monotonic() - started
            finally:
                param.destroy()
    finally:
        proxy.close()
    got = len(every.int_params) + len(every.float_params)
    print(f"MAVSDK get_all_params, {got} parameters, 20 % loss each way: {took:.1f} s; proxy dropped {proxy.dropped}")
    assert got == expected


@pytest.mark.interop
def test_mavproxy_param_fetch_gets_every_parameter_through_20_percent_loss_each_way(gcsd_daemon, spawn, tmp_path):
    pytest.importorskip("MAVProxy", reason="MAVProxy is a test extra: pip install -e .[test]")
    daemon = gcsd_daemon()
    expected = _param_count(daemon.port("gcs"))
    proxy = LossyProxy(daemon.port("gcs"), loss=LOSS, seed=1304)
    argv = [sys.executable, _mavproxy_script(), f"--master=udpout:127.0.0.1:{proxy.port}", "--no-state",
            "--default-modules=param,ftp"]
    process = spawn(argv, name="mavproxy", cwd=tmp_path, env_overrides={"HOME": str(tmp_path)})
    try:
        assert process.output.wait_for(r"Detected vehicle 1:1", 20.0) is not None, process.describe()
        since = len(process.output)
        started = time.monotonic()
        process.send_line("param fetch")
        found = process.output.wait_for(r"Received (\d+) parameters", 120.0, since=since)
        assert found is not None, f"{process.describe()}\n{daemon.describe()}"
        took = time.monotonic() - started
    finally:
        process.stop(5.0, end_of_input_first=True)
        proxy.close()
    print(f"MAVProxy param fetch ({found[2][0]}), 20 % loss each way: {took:.1f} s; proxy dropped {proxy.dropped}")
    assert int(found[2][1]) == expected


def _param_count(port: int) -> int:
    c = Client(udp_url(port), 255, 190)
    try:
        c.heartbeat()
        c.send(M.MAVLink_param_request_read_message(1, 1, b"", 0))
        end = time.monotonic() + 5.0
        while time.monotonic() < end:
            c.read_available()
            for r in c.received:
                if r.type == "PARAM_VALUE":
                    return r.msg.param_count
            time.sleep(0.01)
        pytest.fail("no PARAM_VALUE from the daemon")
    finally:
        c.close()
