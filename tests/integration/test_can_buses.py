"""CAN buses and simulated DroneCAN nodes in one process (python-can `virtual`, the `dronecan` package):
the id conversion at the python-can edge, a bus that cannot open, and the nodes answering a monitor."""

from __future__ import annotations

import itertools
import time

import dronecan
import pytest
from dronecan.app.node_monitor import NodeMonitor

from gcsd.config.can import CanBusConfig
from gcsd.payloads.can.buses import CanBus, CanBusError
from gcsd.payloads.can.forward import EXTENDED_FLAG, CanFrame
from gcsd.payloads.can.nodes import SimNode, _VirtualDriver
from gcsd.vehicle.sim.state import VehicleState

_names = itertools.count()


@pytest.fixture
def channel():
    return f"unit-{next(_names)}"


def test_frames_cross_the_python_can_edge_with_their_extended_flag(channel):
    a, b = CanBus(0, CanBusConfig("virtual", channel)), CanBus(1, CanBusConfig("virtual", channel))
    try:
        assert a.send(CanFrame(0, EXTENDED_FLAG | 0x1401550A, b"\1\2\3"))
        assert a.send(CanFrame(0, 0x123, b"\4"))
        frames = b.poll()
        assert [(f.bus, f.can_id, f.data) for f in frames] == [(1, EXTENDED_FLAG | 0x1401550A, b"\1\2\3"),
                                                               (1, 0x123, b"\4")]
        assert b.poll() == [] and a.poll() == []  # a bus does not hear itself
        assert (a.frames_out, b.frames_in) == (2, 2)
    finally:
        a.close()
        b.close()


def test_a_bus_that_cannot_open_names_itself():
    with pytest.raises(CanBusError, match="can bus 0 .socketcan gcsd-no-such"):
        CanBus(0, CanBusConfig("socketcan", "gcsd-no-such"))


def test_simulated_nodes_answer_node_info_and_publish_the_vehicle(channel):
    state = VehicleState(lat=-35.36, lon=149.16, alt_amsl_m=600.0, home_lat=-35.36, home_lon=149.16, home_alt_m=584.0)
    nodes = [SimNode("gps", 0, channel, lambda: state), SimNode("battery", 0, channel, lambda: state)]
    monitor_node = dronecan.node.Node(_VirtualDriver(channel), node_id=127)
    monitor = NodeMonitor(monitor_node)
    fixes, batteries = [], []
    monitor_node.add_handler(dronecan.uavcan.equipment.gnss.Fix2, lambda e: fixes.append(e.message))
    monitor_node.add_handler(dronecan.uavcan.equipment.power.BatteryInfo, lambda e: batteries.append(e.message))
    try:
        for _ in range(300):  # dronecan's scheduler keeps real time: up to 3 s
            for n in nodes:
                n.spin()
            monitor_node.spin(0.01)
            if fixes and batteries and all(monitor.exists(i) and monitor.get(i).info for i in (10, 11)):
                break
        assert bytes(monitor.get(10).info.name).decode() == "org.gcsd.gps"
        assert bytes(monitor.get(11).info.name).decode() == "org.gcsd.battery"
        assert fixes[-1].latitude_deg_1e8 == round(-35.36 * 1e8) and fixes[-1].height_msl_mm == 600_000
        assert batteries[-1].state_of_charge_pct == 100
    finally:
        for n in nodes:
            n.close()
        monitor_node.close()


def test_frames_cross_the_mavlink_bridge_both_ways_classic_and_fd(daemon, client, channel):
    """The daemon in this process shares python-can's virtual bus with the test: a frame on the bus
    reaches a forwarding client as CAN_FRAME / CANFD_FRAME, a client's frames reach the bus."""
    from pymavlink.dialects.v20 import ardupilotmega as M

    from .helpers import wait_for

    d = daemon({"can": {"buses": [{"interface": "virtual", "channel": channel, "fd": True}]},
                "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]})
    gcs = client(f"udpout:127.0.0.1:{d.port('gcs')}", 250, 189)
    bus = CanBus(0, CanBusConfig("virtual", channel, fd=True))
    try:
        gcs.heartbeat()
        assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == (1, 1))
        mark = gcs.mark()
        gcs.command_long(M.MAV_CMD_CAN_FORWARD, 1)
        assert wait_for(gcs, lambda r: r.type == "COMMAND_ACK" and r.msg.result == M.MAV_RESULT_ACCEPTED, since=mark)
        assert bus.send(CanFrame(0, EXTENDED_FLAG | 0x1401550A, b"\1\2\3"))
        assert bus.send(CanFrame(0, EXTENDED_FLAG | 0x100, bytes(range(12)), fd=True))
        classic = wait_for(gcs, lambda r: r.type == "CAN_FRAME", since=mark)
        fd = wait_for(gcs, lambda r: r.type == "CANFD_FRAME", since=mark)
        assert classic is not None and (classic.msg.id, classic.msg.len, bytes(classic.msg.data[:3])) == \
            (EXTENDED_FLAG | 0x1401550A, 3, b"\1\2\3")
        assert (classic.msg.target_system, classic.msg.target_component, classic.msg.bus) == (250, 189, 0)
        assert fd is not None and (fd.msg.len, bytes(fd.msg.data[:12])) == (12, bytes(range(12)))
        gcs.send(M.MAVLink_can_frame_message(1, 1, 0, 2, EXTENDED_FLAG | 0x55, b"\7\7" + b"\0" * 6))
        gcs.send(M.MAVLink_canfd_frame_message(1, 1, 0, 20, 0x123, bytes(range(20)) + b"\0" * 44))
        gcs.send(M.MAVLink_can_frame_message(1, 1, 3, 1, 0x1, b"\0" * 8))  # no such bus: refused
        got = []
        deadline = time.monotonic() + 3.0
        while len(got) < 2 and time.monotonic() < deadline:
            got += bus.poll()
            time.sleep(0.01)
        assert [(f.can_id, f.data, f.fd) for f in got] == [(EXTENDED_FLAG | 0x55, b"\7\7", False),
                                                          (0x123, bytes(range(20)), True)]
        assert d.status()["counters"]["can_inbound_refused"] == 1
    finally:
        bus.close()
