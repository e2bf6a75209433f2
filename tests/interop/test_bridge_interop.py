"""The companion-computer bridge with MAVProxy as one of the ground stations.

Setup as tests/integration/bridge.py: a flight-controller gcsd behind a serial null modem and a
companion gcsd (compid 191) with two UDP ground-station channels. MAVProxy on `gcs1` fetches the
flight controller's parameters (PARAM_REQUEST_LIST, through the companion's router) and sets
one; a pymavlink ground station on `gcs2` reads the new value back from the flight controller.
"""

from __future__ import annotations

import re
import time

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as M

from integration.bridge import NullModem, bridge_configs

from .conftest import mavproxy_for_params

pytest.importorskip("MAVProxy", reason="MAVProxy is a test extra: pip install -e .[test]")
pytestmark = pytest.mark.interop

FC = (1, 1)


def read_fc(port: int, name: str, timeout_s: float = 5.0):
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=254, source_component=190)
    conn.mav = M.MAVLink(conn, srcSystem=254, srcComponent=190)
    conn.first_byte = False
    try:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            conn.mav.param_request_read_send(*FC, name.encode(), -1)
            msg = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.5)
            if msg is not None and (msg.get_srcSystem(), msg.get_srcComponent()) == FC and msg.param_id == name:
                return msg
        return None
    finally:
        conn.close()


def test_mavproxy_fetches_and_sets_flight_controller_parameters_through_the_companion(daemon, spawn, tmp_path):
    modem = NullModem()
    daemons = []
    try:
        fc_conf, companion_conf = bridge_configs(tmp_path, modem)
        daemons.append(daemon(fc_conf))
        companion = daemon(companion_conf)
        daemons.append(companion)
        before = read_fc(companion.port("gcs2"), "RC8_TRIM")
        assert before is not None, "the flight controller answers through the bridge"
        mavproxy = mavproxy_for_params(spawn, companion.port("gcs1"), tmp_path)
        mark = len(mavproxy.output)
        mavproxy.send_line("param fetch")
        # MAVProxy fetches the list of every component it detects (the companion's too); the
        # flight controller's is the one with its parameter count
        got = mavproxy.output.wait_for(re.compile(rf"Received {before.param_count} parameters"), 20.0, since=mark)
        assert got is not None, f"every parameter of the flight controller\n{mavproxy.describe()}"
        mavproxy.send_line("param set RC8_TRIM 1466")
        deadline = time.monotonic() + 5
        value = None
        while time.monotonic() < deadline:
            msg = read_fc(companion.port("gcs2"), "RC8_TRIM", 1.0)
            value = msg.param_value if msg else None
            if value == 1466.0:
                break
        assert value == 1466.0, f"the set reached the flight controller ({value})\n{mavproxy.describe()}"
        mavproxy.stop(5.0, end_of_input_first=True)
    finally:
        for d in daemons:
            d.stop()
        modem.close()
