"""A QGroundControl .plan PUT over HTTP, downloaded by MAVSDK (a real ground-station library).

gcsd runs as a subprocess with its HTTP API on an ephemeral port (`http_listening` in its log);
tests/data/qgc/fence_rally.plan is PUT to /v1/vehicles/1/mission, then MAVSDK's `mission_raw`
downloads the geofence and the rally points over UDP as any MAVSDK-based ground station would:
the items are compared with the file itself (commands, vertex counts in param1, radii,
latitudes and longitudes as degE7, rally altitudes).
"""

from __future__ import annotations

import json
from pathlib import Path

import aiohttp
import pytest

pytest.importorskip("mavsdk.asyncio", reason="mavsdk is a test extra: pip install -e .[test]")

from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
from pymavlink.dialects.v20 import ardupilotmega as M

from .test_mission_interop import ground_station

QGC_FILE = Path(__file__).resolve().parents[1] / "data" / "qgc" / "fence_rally.plan"
HTTP_WAIT_S = 10.0
VERTEX = {True: M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, False: M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION}
CIRCLE = {True: M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, False: M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION}


def e7(degrees: float) -> int:
    return round(degrees * 1e7)


def http_url(daemon) -> str:
    found = daemon.process.output.wait_for(r'"http_listening"', HTTP_WAIT_S)
    assert found is not None, f"no http_listening within {HTTP_WAIT_S} s\n{daemon.describe()}"
    return f"http://{json.loads(found[2].string)['address']}"


@pytest.mark.interop
async def test_mavsdk_downloads_the_fence_and_rally_points_of_a_plan_put_over_http(gcsd_daemon):
    daemon = gcsd_daemon({"http": {"address": "127.0.0.1:0"}})
    plan = json.loads(QGC_FILE.read_text(encoding="utf-8"))
    url = f"{http_url(daemon)}/v1/vehicles/1/mission"
    async with aiohttp.ClientSession() as session, \
            session.put(url, data=QGC_FILE.read_bytes(), headers={"Content-Type": "application/json"}) as response:
        assert (response.status, await response.json()) == (200, {"items": 4, "fence": 12, "rally": 3})
    fence = plan["geoFence"]
    expected_fence = [(VERTEX[p["inclusion"]], float(len(p["polygon"])), e7(lat), e7(lon))
                      for p in fence["polygons"] for lat, lon in p["polygon"]]
    expected_fence += [(CIRCLE[c["inclusion"]], float(c["circle"]["radius"]), *map(e7, c["circle"]["center"]))
                       for c in fence["circles"]]
    expected_fence.append((M.MAV_CMD_NAV_FENCE_RETURN_POINT, 0.0, *map(e7, fence["breachReturn"][:2])))
    expected_rally = [(M.MAV_CMD_NAV_RALLY_POINT, e7(lat), e7(lon), float(alt))
                      for lat, lon, alt in plan["rallyPoints"]["points"]]
    async with ground_station(daemon.port("gcs")) as system:
        mission = MissionRawAsync(system)
        try:
            got = await mission.download_geofence()
            assert [(i.command, i.param1, i.x, i.y) for i in got] == expected_fence
            assert [i.mission_type for i in got] == [M.MAV_MISSION_TYPE_FENCE] * 12
            rally = await mission.download_rallypoints()
            assert [(i.command, i.x, i.y, i.z) for i in rally] == expected_rally
        finally:
            mission.destroy()
