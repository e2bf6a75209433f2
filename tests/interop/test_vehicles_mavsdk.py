"""MAVSDK flies gcsd's simulated vehicles (speedup 10): copter, plane and rover.

- `action`: arms a copter, takes off to 10 m, goes to a location 72 m away (DO_REPOSITION),
  returns (RTL) and lands; telemetry shows each stage and, at the end, disarmed at home.
- `mission_raw`: uploads a plan of 10 waypoints (a takeoff first for flying vehicles, an RTL
  last) and starts it; mission progress must reach the end (MISSION_CURRENT and
  MISSION_ITEM_REACHED), and telemetry shows where the vehicle ended up: a copter landed and
  disarmed at home, a plane circling home at its RTL altitude, a rover at the last waypoint.
"""

from __future__ import annotations

import asyncio
import math
import time
from contextlib import asynccontextmanager

import pytest

pytest.importorskip("mavsdk.asyncio", reason="mavsdk is a test extra: pip install -e .[test]")

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.mission_raw import MissionItem, MissionRawAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.sim.geo import distance_m, offset

DISCOVERY_WAIT_S = 5.0
SPEEDUP = 10


@asynccontextmanager
async def flying(port: int):
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    plugins = []
    try:
        await mavsdk.add_any_connection(f"udpout://127.0.0.1:{port}")
        system = await mavsdk.first_autopilot(timeout_s=DISCOVERY_WAIT_S)
        assert system is not None, f"MAVSDK found no autopilot within {DISCOVERY_WAIT_S} s"
        plugins = [TelemetryAsync(system), ActionAsync(system), MissionRawAsync(system)]
        yield plugins
    finally:
        for plugin in plugins:
            plugin.destroy()
        mavsdk.destroy()


async def until(getter, accept, timeout_s: float, what: str):
    """Poll a MAVSDK getter (its latest value) until `accept` takes it."""
    deadline = time.monotonic() + timeout_s
    value = None
    while time.monotonic() < deadline:
        value = await getter()
        if accept(value):
            return value
        await asyncio.sleep(0.1)
    pytest.fail(f"MAVSDK never showed {what} within {timeout_s} s; last value: {value}", pytrace=False)


async def ready(telemetry):
    await until(telemetry.gps_info, lambda g: int(g.fix_type) >= 3, 10.0, "a 3D fix")
    return await until(telemetry.home, lambda h: not math.isnan(h.latitude_deg), 10.0, "home")


@pytest.mark.interop
async def test_mavsdk_action_arms_takes_off_goes_to_a_location_returns_and_lands_a_copter(gcsd_daemon):
    daemon = gcsd_daemon({"vehicle": {"type": "copter", "speedup": SPEEDUP}})
    async with flying(daemon.port("gcs")) as (telemetry, action, _):
        home = await ready(telemetry)
        await action.set_takeoff_altitude(10.0)
        await action.arm()
        await until(telemetry.armed, lambda a: a, 5.0, "armed")
        await action.takeoff()
        await until(telemetry.position, lambda p: p.relative_altitude_m >= 9.5, 30.0, "10 m up")
        lat, lon = offset(home.latitude_deg, home.longitude_deg, 60.0, 40.0)
        await action.goto_location(lat, lon, home.absolute_altitude_m + 15.0, 0.0)
        at = await until(telemetry.position, lambda p: distance_m(p.latitude_deg, p.longitude_deg, lat, lon) < 1.5
                         and abs(p.relative_altitude_m - 15.0) < 1.0, 30.0, "the copter at the location")
        assert at.relative_altitude_m == pytest.approx(15.0, abs=1.0)
        await action.return_to_launch()
        await until(telemetry.armed, lambda a: not a, 60.0, "disarmed after landing")
        await until(telemetry.in_air, lambda v: v is False, 5.0, "on the ground")
        end = await telemetry.position()
        assert distance_m(end.latitude_deg, end.longitude_deg, home.latitude_deg, home.longitude_deg) < 1.0
        assert end.relative_altitude_m == pytest.approx(0.0, abs=0.2)


def _plan(home, vehicle: str) -> list[MissionItem]:
    """Home, (takeoff), 10 waypoints around a circle north of home, (RTL)."""
    spacing, alt = {"copter": (30.0, 15.0), "plane": (250.0, 40.0), "rover": (12.0, 0.0)}[vehicle]
    rel = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    items = [MissionItem(0, M.MAV_FRAME_GLOBAL_INT, M.MAV_CMD_NAV_WAYPOINT, 1, 1, 0, 0, 0, 0,
                         round(home.latitude_deg * 1e7), round(home.longitude_deg * 1e7),
                         home.absolute_altitude_m, 0)]
    if vehicle != "rover":
        items.append(MissionItem(len(items), rel, M.MAV_CMD_NAV_TAKEOFF, 0, 1, 0, 0, 0, 0, 0, 0, alt, 0))
    for i in range(10):
        angle = math.radians(36.0 * i)
        lat, lon = offset(home.latitude_deg, home.longitude_deg, spacing * (1 + math.cos(angle)),
                          spacing * math.sin(angle))
        items.append(MissionItem(len(items), rel, M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0,
                                 round(lat * 1e7), round(lon * 1e7), alt, 0))
    if vehicle != "rover":
        items.append(MissionItem(len(items), rel, M.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0))
    return items


@pytest.mark.interop
@pytest.mark.parametrize("vehicle", ["copter", "plane", "rover"])
async def test_mavsdk_mission_raw_uploads_ten_waypoints_that_are_flown_to_the_end(gcsd_daemon, vehicle):
    daemon = gcsd_daemon({"vehicle": {"type": vehicle, "speedup": SPEEDUP}})
    async with flying(daemon.port("gcs")) as (telemetry, action, mission):
        home = await ready(telemetry)
        plan = _plan(home, vehicle)
        await mission.upload_mission(plan)
        await action.arm()
        await until(telemetry.armed, lambda a: a, 5.0, "armed")
        await mission.start_mission()
        progress = await until(mission.mission_progress, lambda p: p.total == len(plan) and p.current == p.total,
                               120.0, f"mission progress reaching {len(plan)}")
        assert progress.current == len(plan)
        end = await telemetry.position()
        if vehicle == "copter":  # its RTL item lands at home
            await until(telemetry.armed, lambda a: not a, 30.0, "disarmed after the RTL landing")
            end = await telemetry.position()
            assert distance_m(end.latitude_deg, end.longitude_deg, home.latitude_deg, home.longitude_deg) < 1.0
        elif vehicle == "plane":  # back home, circling at RTL_ALTITUDE (100 m)
            end = await until(telemetry.position, lambda p: distance_m(
                p.latitude_deg, p.longitude_deg, home.latitude_deg, home.longitude_deg) < 150.0, 60.0,
                "the plane back home")
            assert end.relative_altitude_m > 35.0
            assert await telemetry.in_air() is True
        else:  # the rover stopped at the last waypoint (at ArduRover's WP_SPEED 5 m/s it brakes for ~12 m)
            await until(telemetry.velocity_ned, lambda v: math.hypot(v.north_m_s, v.east_m_s) < 0.2, 30.0,
                        "the rover stopped")
            end = await telemetry.position()
            last = plan[-1]
            assert distance_m(end.latitude_deg, end.longitude_deg, last.x / 1e7, last.y / 1e7) < 3.0
