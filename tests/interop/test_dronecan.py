"""pydronecan (the DroneCAN GUI Tool's stack) reaches gcsd's simulated CAN bus through its MAVLink CAN
driver (`mavcan:`), against the real daemon (`gcsd run`) with `can.buses` = one virtual bus carrying
a simulated GPS and battery (dronecan nodes 10 and 11).

pydronecan's driver repeats MAV_CMD_CAN_FORWARD every second and sends its frames as CAN_FRAME; its
node monitor sees the nodes' NodeStatus and asks each for GetNodeInfo. A second client (pymavlink,
at the same time) forwards the same bus with a NodeStatus-only filter: better than ArduPilot, both
are served. Forwarding stops 5 s after a client's last CAN_FORWARD.
"""

from __future__ import annotations

import time

import pytest

dronecan = pytest.importorskip("dronecan")

from dronecan.app.node_monitor import NodeMonitor
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as M2

WAIT_S = 15.0
NODE_STATUS_ID = 341


def _config(channel: str) -> dict:
    return {"can": {"buses": [{"interface": "virtual", "channel": channel, "nodes": ["gps", "battery"]}]}}


def _close(node) -> None:
    """Close a mavcan node. Its I/O process cannot exit while frames it queued for us are unread
    (multiprocessing's queue feeder), so they are read until it has gone; bounded."""
    driver = node.can_driver
    driver.exit_queue.put_nowait("QUIT")
    deadline = time.monotonic() + 10.0
    while driver.proc.is_alive() and time.monotonic() < deadline:
        node.spin(0.05)
    if driver.proc.is_alive():
        driver.proc.kill()
    driver.proc.join(2.0)
    driver.proc = None


def _mavlink2(conn):
    """A pymavlink connection pinned to MAVLink2 (CAN_FRAME and CAN_FILTER_MODIFY have ids above 255)."""
    conn.mav = M2.MAVLink(conn, srcSystem=254, srcComponent=190)
    conn.mav.robust_parsing = True
    conn.first_byte = False
    return conn


def _spin_until(node, done, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        node.spin(0.05)
        if done():
            return True
    return False


def _can_frames(conn, seconds: float) -> list:
    """The CAN_FRAMEs addressed to this client (a UDP channel's peers all hear the channel)."""
    frames, deadline = [], time.monotonic() + seconds
    while time.monotonic() < deadline:
        m = conn.recv_match(type=["CAN_FRAME", "COMMAND_ACK"], blocking=True, timeout=0.1)
        if m is not None and m.get_type() == "CAN_FRAME" and m.target_system == conn.mav.srcSystem:
            frames.append(m)
    return frames


@pytest.mark.interop
def test_pydronecan_sees_the_simulated_nodes_and_reads_get_node_info(gcsd_daemon, tmp_path):
    daemon = gcsd_daemon(_config(f"gcsd-{tmp_path.name}"))
    port = daemon.port("gcs")
    gui = dronecan.make_node(f"mavcan:udpout:127.0.0.1:{port}", node_id=127, bus_number=1)
    other = _mavlink2(mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=254, source_component=190))
    try:
        monitor = NodeMonitor(gui)

        def both_known() -> bool:
            ids = set(monitor.get_all_node_id())
            return {10, 11} <= ids and all(monitor.get(i).info is not None for i in (10, 11))

        assert _spin_until(gui, both_known, WAIT_S), f"nodes seen: {list(monitor.get_all_node_id())}"
        gps, battery = monitor.get(10).info, monitor.get(11).info
        assert bytes(gps.name).decode() == "org.gcsd.gps"
        assert bytes(battery.name).decode() == "org.gcsd.battery"
        assert gps.software_version.major == 1
        assert monitor.get(10).status.mode == monitor.get(10).status.MODE_OPERATIONAL

        # a parameter read and write through the bridge (uavcan.protocol.param.GetSet)
        answers = []
        request = dronecan.uavcan.protocol.param.GetSet.Request(name="GPS_RATE_HZ")
        gui.request(request, 10, lambda e: answers.append(e))
        assert _spin_until(gui, lambda: answers, 5.0), "no GetSet response"
        assert answers[0] is not None and answers[0].response.value.integer_value == 5
        answers.clear()
        request = dronecan.uavcan.protocol.param.GetSet.Request(
            name="GPS_RATE_HZ", value=dronecan.uavcan.protocol.param.Value(integer_value=10))
        gui.request(request, 10, lambda e: answers.append(e))
        assert _spin_until(gui, lambda: answers, 5.0) and answers[0].response.value.integer_value == 10

        # a second client on the same bus, at the same time, with a NodeStatus-only filter
        other.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_CAN_FORWARD, 0, 1, 0, 0, 0, 0, 0, 0)
        ack = other.recv_match(type="COMMAND_ACK", blocking=True, timeout=3)
        assert ack is not None and ack.result == mavutil.mavlink.MAV_RESULT_ACCEPTED
        other.mav.can_filter_modify_send(1, 1, 1, mavutil.mavlink.CAN_FILTER_REPLACE, 1,
                                         [NODE_STATUS_ID] + [0] * 15)
        _can_frames(other, 0.5)  # what was on its way before the filter
        frames = _can_frames(other, 2.5)
        assert frames, "the second client got no frames"
        assert all((f.id >> 8) & 0xFFFF == NODE_STATUS_ID for f in frames)
        assert {f.id & 0x7F for f in frames} == {10, 11}
        assert _spin_until(gui, lambda: monitor.get(10).status.uptime_sec >= 2, 5.0)  # the first still served

        # no more CAN_FORWARD from the second client: it stops getting frames after 5 s (the GUI keeps
        # running meanwhile, as a GUI does)
        _spin_until(gui, lambda: False, 5.5)
        _can_frames(other, 0.3)  # what waited in our socket from before the timeout
        late = _can_frames(other, 1.5)
        assert not late, f"{len(late)} frames after the 5 s timeout"
        before = monitor.get(10).status.uptime_sec
        assert _spin_until(gui, lambda: monitor.get(10).status.uptime_sec > before, 5.0)  # positive control
        other.mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_CAN_FORWARD, 0, 3, 0, 0, 0, 0, 0, 0)
        ack = other.recv_match(type="COMMAND_ACK", blocking=True, timeout=3)
        assert ack is not None and ack.result == mavutil.mavlink.MAV_RESULT_FAILED  # bus 2: not configured
    finally:
        other.close()
        _close(gui)
