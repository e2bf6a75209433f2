"""CAN buses and simulated DroneCAN nodes in one process (python-can `virtual`, the `dronecan` package):
the id conversion at the python-can edge, a bus that cannot open, and the nodes answering a monitor."""

from __future__ import annotations

import itertools

import dronecan
import pytest
from dronecan.app.node_monitor import NodeMonitor

from gcsd.can.buses import CanBus, CanBusError
from gcsd.can.forward import EXTENDED_FLAG, CanFrame
from gcsd.can.nodes import SimNode, _VirtualDriver
from gcsd.config_can import CanBusConfig
from gcsd.sim.state import VehicleState

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
