"""What real clients conclude from gcsd's SYS_STATUS, as they would from ArduPilot's.

- MAVSDK's `telemetry.health().is_armable` comes from SYS_STATUS's PREARM_CHECK bit: True with the
  defaults (the pre-arm checks pass and arming works), False once a check fails (a compass whose
  offsets read as never calibrated), True again once it is fixed.
- MAVProxy's fence module says "fence breach" when SYS_STATUS's GEOFENCE health bit drops; gcsd
  reports the fence present and healthy, so on connect MAVProxy (all its default modules) says
  "fence present" (the positive control: the module read SYS_STATUS) and never "fence breach",
  nor any other warning.
"""

from __future__ import annotations

import asyncio
import re
import sys
import time

import pytest

from .conftest import expect_line, mavproxy_script

pytest.importorskip("mavsdk.asyncio", reason="mavsdk is a test extra: pip install -e .[test]")

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

DISCOVERY_WAIT_S = 5.0


async def _health_until(telemetry, accept, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    health = None
    while time.monotonic() < deadline:
        health = await telemetry.health()
        if accept(health):
            return health
        await asyncio.sleep(0.1)
    pytest.fail(f"MAVSDK never showed {what} within {timeout_s} s; last health: {health}", pytrace=False)


@pytest.mark.interop
async def test_mavsdk_is_armable_follows_the_prearm_checks(gcsd_daemon):
    daemon = gcsd_daemon()
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    plugins = []
    try:
        await mavsdk.add_any_connection(f"udpout://127.0.0.1:{daemon.port('gcs')}")
        system = await mavsdk.first_autopilot(timeout_s=DISCOVERY_WAIT_S)
        assert system is not None
        telemetry, param = TelemetryAsync(system), ParamAsync(system)
        plugins = [telemetry, param]
        healthy = await _health_until(telemetry, lambda h: h.is_armable, 10.0, "is_armable True")
        assert healthy.is_global_position_ok and healthy.is_home_position_ok
        offsets = [await param.get_param_float(f"COMPASS_OFS_{axis}") for axis in "XYZ"]
        for axis in "XYZ":  # all zero: the compass reads as never calibrated
            await param.set_param_float(f"COMPASS_OFS_{axis}", 0.0)
        await _health_until(telemetry, lambda h: not h.is_armable, 5.0, "is_armable False with an uncalibrated compass")
        for axis, value in zip("XYZ", offsets):
            await param.set_param_float(f"COMPASS_OFS_{axis}", value)
        await _health_until(telemetry, lambda h: h.is_armable, 5.0, "is_armable True again")
    finally:
        for plugin in plugins:
            plugin.destroy()
        mavsdk.destroy()


WARNINGS = re.compile(r"fence breach|fence disabled|PreArm|Failsafe|failsafe|unhealthy|EKF.*(fail|reset)|"
                      r"Bad |bad data|link \d+ down|no link|timeout|error", re.IGNORECASE)


@pytest.mark.interop
def test_mavproxy_connects_without_a_spurious_fence_breach_or_other_warning(gcsd_daemon, spawn, tmp_path):
    """MAVProxy with its default modules, as a user starts it; positive controls from the same
    output: the fence module's "fence present" and the parameter download over FTP."""
    daemon = gcsd_daemon()
    process = spawn(
        [sys.executable, mavproxy_script(), f"--master=udpout:127.0.0.1:{daemon.port('gcs')}", "--no-state"],
        name="mavproxy", cwd=tmp_path, env_overrides={"HOME": str(tmp_path)},
    )
    try:
        expect_line(process, daemon, r"Detected vehicle 1:1 on link 0", 10.0, 0, "the vehicle")
        expect_line(process, daemon, r"fence present", 10.0, 0, "that the fence module read SYS_STATUS")
        expect_line(process, daemon, r"Received \d+ parameters \(ftp\)", 15.0, 0, "the parameters")
        # a later SYS_STATUS has been through the same handlers once MAVProxy answers `status SYS_STATUS`
        since = len(process.output)
        process.send_line("status SYS_STATUS")
        expect_line(process, daemon, r"SYS_STATUS \{", 5.0, since, "the last SYS_STATUS")
        connect_output = process.output.lines()[:since]  # up to our own `status` command
        warnings = [line for _, line in connect_output if WARNINGS.search(line)]
        assert not warnings, f"MAVProxy warned on connect: {warnings}\n{process.describe()}"
    finally:
        process.stop(5.0, end_of_input_first=True)


@pytest.mark.interop
def test_mavproxy_runs_the_compass_and_accelerometer_calibrations(gcsd_daemon, spawn, tmp_path):
    """MAVProxy's calibration module: `magcal start` (autosave) prints each compass's report;
    `accelcal` waits for each "Place vehicle ..." and answers the Enter key with a COMMAND_ACK."""
    daemon = gcsd_daemon()
    process = spawn(
        [sys.executable, mavproxy_script(), f"--master=udpout:127.0.0.1:{daemon.port('gcs')}", "--no-state",
         "--default-modules=mode,arm,calibration"],
        name="mavproxy", cwd=tmp_path, env_overrides={"HOME": str(tmp_path)},
    )
    try:
        expect_line(process, daemon, r"Detected vehicle 1:1 on link 0", 10.0, 0, "the vehicle")
        since = len(process.output)
        process.send_line("magcal start")
        expect_line(process, daemon, r"Calibration of compass 0 SUCCESS: fitness", 10.0, since, "compass 0's report")
        since = len(process.output)
        process.send_line("accelcal")
        for where in ("level", "on its LEFT side", "on its RIGHT side", "nose DOWN", "nose UP", "on its BACK"):
            index, _, _ = expect_line(process, daemon, rf"Place vehicle {where} and press any key", 5.0, since, where)
            since = index + 1
            process.send_line("")  # the Enter key
        expect_line(process, daemon, r"Calibration successful", 5.0, since, "the end of the accelerometer calibration")
    finally:
        process.stop(5.0, end_of_input_first=True)
