"""MAVProxy, headless, drives gcsd: it must find the copter within 2 s, see its mode, GPS fix and
position, change its mode to GUIDED, arm it and disarm it.

MAVProxy runs as its users run it against a vehicle on UDP:
`mavproxy.py --master=udpout:127.0.0.1:PORT --no-state --default-modules=mode,arm`, commands fed
line by line on stdin. (`--non-interactive` is not used: with it MAVProxy never reads stdin.)
Its console output is the observable: "Detected vehicle 1:1 on link 0", "Mode STABILIZE",
"GPS lock at 584 meters", "Got COMMAND_ACK: ...: ACCEPTED", "ARMED", and `status NAME`
(GLOBAL_POSITION_INT, HEARTBEAT, GPS_RAW_INT), which prints the last such message decoded.
"""

from __future__ import annotations

import re
import sys

import pytest

pytest.importorskip("MAVProxy", reason="MAVProxy is a test extra: pip install -e .[test]")

CONNECT_LIMIT_S = 2.0
# A mode change is announced ("Mode X") at most once per 2 s, on the next heartbeat after that.
MODE_ANNOUNCE_WAIT_S = 4.0
ACK_WAIT_S = 3.0
HEARTBEAT_STATE_WAIT_S = 3.0
POSITION_TOLERANCE_1E7 = 100  # 1e-5 degree
ALTITUDE_TOLERANCE_MM = 1000

HEARTBEAT_LINE = re.compile(
    r"HEARTBEAT \{type : (?P<type>\d+), autopilot : (?P<autopilot>\d+), base_mode : (?P<base_mode>\d+), "
    r"custom_mode : (?P<custom_mode>\d+), system_status : (?P<system_status>\d+)"
)
MAV_TYPE_QUADROTOR = 2
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_MODE_FLAG_SAFETY_ARMED = 128
COPTER_STABILIZE = 0
COPTER_GUIDED = 4
GPS_RAW_INT_LINE = re.compile(
    r"GPS_RAW_INT \{time_usec : \d+, fix_type : (?P<fix_type>\d+), lat : (?P<lat>-?\d+), lon : (?P<lon>-?\d+)"
)
GPS_FIX_TYPE_3D_FIX = 3
GLOBAL_POSITION_INT_LINE = re.compile(
    r"GLOBAL_POSITION_INT \{time_boot_ms : \d+, lat : (?P<lat>-?\d+), lon : (?P<lon>-?\d+), "
    r"alt : (?P<alt>-?\d+), relative_alt : (?P<relative_alt>-?\d+)"
)
from .conftest import expect_line as _expect
from .conftest import mavproxy_script as _mavproxy_script


@pytest.fixture
def mavproxy(spawn, tmp_path):
    """Factory: mavproxy(port) -> SpawnedProcess of a headless MAVProxy connected to that port.

    It runs in tmp_path with HOME=tmp_path, so no startup script or key file of the user's is read
    and anything it writes stays in tmp_path. Stopped by closing its stdin (it then exits as on
Ctrl-D; `exit` is refused unless its `requireexit` setting is on), then SIGTERM, SIGKILL.
    """
    started = []

    def start(port: int):
        process = spawn(
            [
                sys.executable,
                _mavproxy_script(),
                f"--master=udpout:127.0.0.1:{port}",
                "--no-state",
                "--default-modules=mode,arm",
            ],
            name="mavproxy",
            cwd=tmp_path,
            env_overrides={"HOME": str(tmp_path)},
        )
        started.append(process)
        return process

    yield start
    for process in started:
        process.stop(5.0, end_of_input_first=True)


def _last_message(process, daemon, name: str, line: re.Pattern, timeout_s: float = 3.0) -> re.Match:
    """Ask `status NAME` (MAVProxy prints the last such message decoded) until it has one."""
    attempts = int(timeout_s / 0.5)
    for _ in range(attempts):
        since = len(process.output)
        process.send_line(f"status {name}")
        found = process.output.wait_for(line, 0.5, since=since)
        if found is not None:
            return found[2]
    pytest.fail(
        f"MAVProxy never had a {name} to show within {timeout_s} s\n"
        f"{process.describe()}\n\n{daemon.describe()}",
        pytrace=False,
    )


@pytest.mark.interop
def test_mavproxy_detects_copter_within_2s_and_sees_mode_gps_and_home_position(
    gcsd_daemon, mavproxy, home_position
):
    daemon = gcsd_daemon()
    process = mavproxy(daemon.port("gcs"))

    # MAVProxy prints this once its UDP link is open and it starts sending heartbeats.
    link_index, link_opened_at, _ = _expect(
        process, daemon, r"Waiting for heartbeat from 127\.0\.0\.1:\d+", 10.0, 0, "that its link is open"
    )
    detected_index, detected_at, _ = _expect(
        process, daemon, r"Detected vehicle 1:1 on link 0", 5.0, link_index, "the vehicle's heartbeat"
    )
    _, mode_at, _ = _expect(process, daemon, r"Mode STABILIZE$", 5.0, link_index, "the mode STABILIZE")
    connect_s = detected_at - link_opened_at
    print(
        f"MAVProxy: link open {link_opened_at - process.started_at:.3f} s after start; "
        f"vehicle detected {connect_s:.3f} s and mode shown {mode_at - link_opened_at:.3f} s after that"
    )
    assert connect_s < CONNECT_LIMIT_S, f"vehicle detected {connect_s:.3f} s after MAVProxy's link opened"
    assert mode_at - link_opened_at < CONNECT_LIMIT_S, (
        f"mode shown {mode_at - link_opened_at:.3f} s after MAVProxy's link opened"
    )
    _expect(process, daemon, r"online system 1$", 1.0, detected_index, "that system 1 is its target")

    position = _last_message(process, daemon, "GLOBAL_POSITION_INT", GLOBAL_POSITION_INT_LINE)
    assert abs(int(position["lat"]) - round(home_position.lat_deg * 1e7)) <= POSITION_TOLERANCE_1E7, position[0]
    assert abs(int(position["lon"]) - round(home_position.lon_deg * 1e7)) <= POSITION_TOLERANCE_1E7, position[0]
    assert abs(int(position["alt"]) - round(home_position.alt_m * 1000)) <= ALTITUDE_TOLERANCE_MM, position[0]
    assert abs(int(position["relative_alt"])) <= ALTITUDE_TOLERANCE_MM, position[0]

    heartbeat = _last_message(process, daemon, "HEARTBEAT", HEARTBEAT_LINE)
    assert int(heartbeat["type"]) == MAV_TYPE_QUADROTOR, heartbeat[0]
    assert int(heartbeat["autopilot"]) == MAV_AUTOPILOT_ARDUPILOTMEGA, heartbeat[0]
    assert int(heartbeat["custom_mode"]) == COPTER_STABILIZE, heartbeat[0]
    assert not int(heartbeat["base_mode"]) & MAV_MODE_FLAG_SAFETY_ARMED, heartbeat[0]
    # MAVProxy announces ARMED only on a change, so it must not have.
    assert process.output.wait_for(r"(?:^|> )ARMED$", 0.0) is None, process.describe()

    gps = _last_message(process, daemon, "GPS_RAW_INT", GPS_RAW_INT_LINE)
    assert int(gps["fix_type"]) >= GPS_FIX_TYPE_3D_FIX, gps[0]
    assert abs(int(gps["lat"]) - round(home_position.lat_deg * 1e7)) <= POSITION_TOLERANCE_1E7, gps[0]
    assert abs(int(gps["lon"]) - round(home_position.lon_deg * 1e7)) <= POSITION_TOLERANCE_1E7, gps[0]

    # MAVProxy announces "GPS lock at N meters" on the first VFR_HUD with a non-zero alt once
    # GPS_RAW_INT has a 3D fix; VFR_HUD.alt is the altitude above mean sea level (MAVLink
    # common.xml; ArduCopter sends the AMSL altitude by default), so N is home's altitude.
    home_alt_m = int(home_position.alt_m)
    _expect(
        process,
        daemon,
        rf"GPS lock at {home_alt_m} meters",
        5.0,
        link_index,
        f"a 3D GPS lock at {home_alt_m} m (VFR_HUD.alt must be the AMSL altitude)",
    )


@pytest.mark.interop
def test_mavproxy_sets_guided_then_arms_and_disarms(gcsd_daemon, mavproxy):
    daemon = gcsd_daemon()
    process = mavproxy(daemon.port("gcs"))
    _expect(process, daemon, r"Mode STABILIZE$", 10.0, 0, "the mode STABILIZE")
    _last_message(process, daemon, "GLOBAL_POSITION_INT", GLOBAL_POSITION_INT_LINE)  # has a position

    since = len(process.output)
    process.send_line("mode GUIDED")
    _expect(process, daemon, r"Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", ACK_WAIT_S, since, "DO_SET_MODE accepted")
    _expect(process, daemon, r"Mode GUIDED$", MODE_ANNOUNCE_WAIT_S, since, "the heartbeat's mode GUIDED")

    since = len(process.output)
    process.send_line("arm throttle")
    _expect(
        process, daemon, r"Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED", ACK_WAIT_S, since, "arming accepted"
    )
    armed_index, _, _ = _expect(
        process, daemon, r"(?:^|> )ARMED$", HEARTBEAT_STATE_WAIT_S, since, "the heartbeat's armed flag"
    )
    assert process.output.wait_for(r"(?:^|> )DISARMED$", 0.0, since=armed_index) is None, process.describe()

    heartbeat = _last_message(process, daemon, "HEARTBEAT", HEARTBEAT_LINE)
    assert int(heartbeat["custom_mode"]) == COPTER_GUIDED, heartbeat[0]
    assert int(heartbeat["base_mode"]) & MAV_MODE_FLAG_SAFETY_ARMED, heartbeat[0]

    since = len(process.output)
    process.send_line("disarm")
    _expect(
        process, daemon, r"Got COMMAND_ACK: COMPONENT_ARM_DISARM: ACCEPTED", ACK_WAIT_S, since, "disarming accepted"
    )
    _expect(process, daemon, r"(?:^|> )DISARMED$", HEARTBEAT_STATE_WAIT_S, since, "the heartbeat's disarmed state")
