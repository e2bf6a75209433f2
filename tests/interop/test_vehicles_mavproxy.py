"""MAVProxy, headless, flies gcsd's simulated copter and names every vehicle type's modes.

- Copter at speedup 10: `mode GUIDED`, `arm throttle`, `takeoff 10` (MAV_CMD_NAV_TAKEOFF,
  the cmdlong module), the altitude reaches 10 m, `mode RTL` brings it home, it lands and
  disarms by itself.
- For copter, plane, rover, sub, tracker and blimp, MAVProxy prints the initial mode's name
  from the heartbeat (pymavlink's mode map for that MAV_TYPE), and `mode X` to another mode
  is acknowledged and announced by name.
"""

from __future__ import annotations

import re
import sys
import time

import pytest

from .conftest import expect_line as _expect
from .conftest import mavproxy_script as _mavproxy_script

pytest.importorskip("MAVProxy", reason="MAVProxy is a test extra: pip install -e .[test]")

ACK_WAIT_S = 3.0
MODE_WAIT_S = 5.0
GLOBAL_POSITION_INT_LINE = re.compile(r"GLOBAL_POSITION_INT \{time_boot_ms : \d+, lat : -?\d+, lon : -?\d+, "
                                      r"alt : -?\d+, relative_alt : (?P<relative_alt>-?\d+)")


@pytest.fixture
def mavproxy(spawn, tmp_path):
    started = []

    def start(port: int):
        process = spawn(
            [sys.executable, _mavproxy_script(), f"--master=udpout:127.0.0.1:{port}", "--no-state",
             "--default-modules=mode,arm,cmdlong"],
            name="mavproxy", cwd=tmp_path, env_overrides={"HOME": str(tmp_path)},
        )
        started.append(process)
        return process

    yield start
    for process in started:
        process.stop(5.0, end_of_input_first=True)


def _relative_alt_m(process, daemon, timeout_s: float, accept) -> float:
    """Ask `status GLOBAL_POSITION_INT` until its relative altitude is acceptable."""
    value = None
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        time.sleep(0.3)
        since = len(process.output)
        process.send_line("status GLOBAL_POSITION_INT")
        found = process.output.wait_for(GLOBAL_POSITION_INT_LINE, 0.5, since=since)
        if found is not None:
            value = int(found[2]["relative_alt"]) / 1000.0
            if accept(value):
                return value
    pytest.fail(f"relative altitude never acceptable within {timeout_s} s (last {value})\n{process.describe()}",
                pytrace=False)


@pytest.mark.interop
def test_mavproxy_guided_arm_throttle_takeoff_10_then_rtl_lands_the_copter(gcsd_daemon, mavproxy):
    daemon = gcsd_daemon({"vehicle": {"type": "copter", "speedup": 10}})
    process = mavproxy(daemon.port("gcs"))
    _expect(process, daemon, r"Mode STABILIZE$", 10.0, 0, "the mode STABILIZE")
    _relative_alt_m(process, daemon, 3.0, lambda alt: True)

    since = len(process.output)
    process.send_line("mode GUIDED")
    _expect(process, daemon, r"Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", ACK_WAIT_S, since, "GUIDED accepted")
    _expect(process, daemon, r"Mode GUIDED$", MODE_WAIT_S, since, "the mode GUIDED")

    since = len(process.output)
    process.send_line("arm throttle")
    _expect(process, daemon, r"Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED", ACK_WAIT_S, since, "arming accepted")
    _expect(process, daemon, r"(?:^|> )ARMED$", MODE_WAIT_S, since, "ARMED")

    since = len(process.output)
    process.send_line("takeoff 10")
    _expect(process, daemon, r"Got COMMAND_ACK: NAV_TAKEOFF: ACCEPTED", ACK_WAIT_S, since, "takeoff accepted")
    assert _relative_alt_m(process, daemon, 20.0, lambda alt: alt >= 9.5) == pytest.approx(10.0, abs=0.6)

    since = len(process.output)
    process.send_line("mode RTL")
    _expect(process, daemon, r"Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", ACK_WAIT_S, since, "RTL accepted")
    _expect(process, daemon, r"Mode RTL$", MODE_WAIT_S, since, "the mode RTL")
    _expect(process, daemon, r"(?:^|> )DISARMED$", 40.0, since, "DISARMED after the RTL landing")
    assert _relative_alt_m(process, daemon, 3.0, lambda alt: abs(alt) < 0.3) == pytest.approx(0.0, abs=0.3)


@pytest.mark.interop
@pytest.mark.parametrize("vehicle, initial, other", [
    ("copter", "STABILIZE", "ALT_HOLD"), ("plane", "MANUAL", "FBWA"), ("rover", "MANUAL", "HOLD"),
    ("sub", "MANUAL", "ALT_HOLD"), ("tracker", "MANUAL", "STOP"), ("blimp", "MANUAL", "LOITER"),
])
def test_mavproxy_shows_each_vehicle_types_mode_names(gcsd_daemon, mavproxy, vehicle, initial, other):
    daemon = gcsd_daemon({"vehicle": {"type": vehicle}})
    process = mavproxy(daemon.port("gcs"))
    _expect(process, daemon, rf"Mode {initial}$", 10.0, 0, f"the initial mode {initial}")
    since = len(process.output)
    process.send_line(f"mode {other}")
    _expect(process, daemon, r"Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", ACK_WAIT_S, since, f"{other} accepted")
    _expect(process, daemon, rf"Mode {other}$", MODE_WAIT_S, since, f"the mode {other}")
