"""MAVSDK (the `mavsdk` package, 4.x: the C++ core through ctypes, no mavsdk_server) drives gcsd.

It connects as a ground station with `udpout://127.0.0.1:PORT`, must discover the autopilot
within 2 s, and then reads what every MAVSDK application reads first: flight mode (from the
HEARTBEAT's ArduCopter custom_mode), armed state, GLOBAL_POSITION_INT, GPS fix and the home
position (which MAVSDK asks for with MAV_CMD_REQUEST_MESSAGE HOME_POSITION). It arms and disarms
with the action plugin (MAV_CMD_COMPONENT_ARM_DISARM, answered with COMMAND_ACK) and waits for the
heartbeat to show each change.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import aclosing, asynccontextmanager

import pytest

pytest.importorskip("mavsdk.asyncio", reason="mavsdk is a test extra: pip install -e .[test]")

from mavsdk.asyncio import Autopilot, ComponentType, Configuration, Mavsdk, System, Vehicle
from mavsdk.asyncio.plugins.action import ActionAsync, ActionError
from mavsdk.asyncio.plugins.telemetry import FixType, FlightMode, TelemetryAsync

CONNECT_LIMIT_S = 2.0
DISCOVERY_WAIT_S = 5.0  # longer than the limit, so a slow discovery is measured, not just failed
TELEMETRY_WAIT_S = 3.0  # heartbeats come at 1 Hz; streams at their default rates
POSITION_TOLERANCE_DEG = 1e-5
ALTITUDE_TOLERANCE_M = 1.0


async def _first(
    stream: AsyncIterator,
    accept: Callable[[object], bool],
    timeout_s: float,
    what: str,
    current: Callable[[], Awaitable[object]] | None = None,
):
    """The first value from a MAVSDK subscription that `accept` takes, within `timeout_s`.

    With `current` (the plugin's getter of the latest value), that value is taken if it is
    acceptable: a subscription only reports updates, and some messages (HOME_POSITION, sent once
    on MAVSDK's request at connection) may have arrived before it started.
    """
    seen = []
    if current is not None:
        value = await current()
        if accept(value):
            await stream.aclose()
            return value
        seen.append(value)
    try:
        async with aclosing(stream) as values, asyncio.timeout(timeout_s):
            async for value in values:
                if accept(value):
                    return value
                seen.append(value)
    except TimeoutError:
        pass
    last = [str(v) for v in seen[-3:]]
    pytest.fail(f"MAVSDK reported no {what} within {timeout_s} s; last values seen: {last}", pytrace=False)


@asynccontextmanager
async def _ground_station(port: int):
    """A MAVSDK ground station connected to 127.0.0.1:port; yields (mavsdk, seconds to connect, system).

    The time is from add_any_connection() to first_autopilot() returning the system.
    """
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        started = time.monotonic()
        await mavsdk.add_any_connection(f"udpout://127.0.0.1:{port}")
        system = await mavsdk.first_autopilot(timeout_s=DISCOVERY_WAIT_S)
        connect_s = time.monotonic() - started
        yield mavsdk, connect_s, system
    finally:
        mavsdk.destroy()


@asynccontextmanager
async def _plugins(system: System):
    telemetry, action = TelemetryAsync(system), ActionAsync(system)
    try:
        yield telemetry, action
    finally:
        telemetry.destroy()
        action.destroy()


@pytest.mark.interop
async def test_mavsdk_finds_autopilot_within_2s_and_reads_mode_armed_and_position(
    gcsd_daemon, home_position
):
    daemon = gcsd_daemon()
    async with _ground_station(daemon.port("gcs")) as (_, connect_s, system):
        assert system is not None, f"no autopilot within {DISCOVERY_WAIT_S} s\n{daemon.describe()}"
        print(f"MAVSDK: first_autopilot after {connect_s:.3f} s")
        assert connect_s < CONNECT_LIMIT_S, f"autopilot discovered only after {connect_s:.3f} s"
        assert await system.get_system_id() == 1
        assert 1 in await system.component_ids()
        assert await system.autopilot_type() == Autopilot.ARDUPILOT
        assert await system.vehicle_type() == Vehicle.MULTICOPTER

        async with _plugins(system) as (telemetry, _):
            # ArduCopter STABILIZE (custom_mode 0) is MAVSDK's STABILIZED.
            mode = await _first(
                telemetry.subscribe_flight_mode(), lambda m: m != FlightMode.UNKNOWN, TELEMETRY_WAIT_S, "flight mode"
            )
            assert mode == FlightMode.STABILIZED, mode

            armed = await _first(telemetry.subscribe_armed(), lambda a: True, TELEMETRY_WAIT_S, "armed state")
            assert armed is False

            position = await _first(
                telemetry.subscribe_position(),
                lambda p: not math.isnan(p.latitude_deg),
                TELEMETRY_WAIT_S,
                "position",
                telemetry.position,
            )
            assert position.latitude_deg == pytest.approx(home_position.lat_deg, abs=POSITION_TOLERANCE_DEG)
            assert position.longitude_deg == pytest.approx(home_position.lon_deg, abs=POSITION_TOLERANCE_DEG)
            assert position.absolute_altitude_m == pytest.approx(home_position.alt_m, abs=ALTITUDE_TOLERANCE_M)
            assert position.relative_altitude_m == pytest.approx(0.0, abs=ALTITUDE_TOLERANCE_M)

            gps = await _first(
                telemetry.subscribe_gps_info(),
                lambda g: g.fix_type != FixType.NO_GPS or g.num_satellites > 0,
                TELEMETRY_WAIT_S,
                "GPS info",
                telemetry.gps_info,
            )
            assert gps.fix_type == FixType.FIX_3D, gps
            assert gps.num_satellites > 0, gps

            home = await _first(
                telemetry.subscribe_home(),
                lambda h: not math.isnan(h.latitude_deg),
                TELEMETRY_WAIT_S,
                "home position",
                telemetry.home,
            )
            assert home.latitude_deg == pytest.approx(home_position.lat_deg, abs=POSITION_TOLERANCE_DEG)
            assert home.longitude_deg == pytest.approx(home_position.lon_deg, abs=POSITION_TOLERANCE_DEG)
            assert home.absolute_altitude_m == pytest.approx(home_position.alt_m, abs=ALTITUDE_TOLERANCE_M)


@pytest.mark.interop
async def test_mavsdk_arms_and_disarms_with_the_action_plugin(gcsd_daemon):
    daemon = gcsd_daemon()
    async with _ground_station(daemon.port("gcs")) as (_, _, system):
        assert system is not None, f"no autopilot within {DISCOVERY_WAIT_S} s\n{daemon.describe()}"
        async with _plugins(system) as (telemetry, action):
            assert await _first(telemetry.subscribe_armed(), lambda a: True, TELEMETRY_WAIT_S, "armed state") is False
            # Arming checks need a 3D fix; wait for it as a ground station operator would.
            await _first(
                telemetry.subscribe_gps_info(),
                lambda g: g.fix_type >= FixType.FIX_3D,
                TELEMETRY_WAIT_S,
                "3D fix",
                telemetry.gps_info,
            )

            try:
                await action.arm()
            except ActionError as error:
                pytest.fail(f"arm() failed: {error}\n{daemon.describe()}", pytrace=False)
            await _first(telemetry.subscribe_armed(), lambda a: a is True, TELEMETRY_WAIT_S, "armed = True")
            assert await telemetry.flight_mode() == FlightMode.STABILIZED

            try:
                await action.disarm()
            except ActionError as error:
                pytest.fail(f"disarm() failed: {error}\n{daemon.describe()}", pytrace=False)
            await _first(telemetry.subscribe_armed(), lambda a: a is False, TELEMETRY_WAIT_S, "armed = False")
