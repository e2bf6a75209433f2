"""Simulated DroneCAN nodes on a `virtual` bus, built with the `dronecan` package (pydronecan).

Each node is a real `dronecan.node.Node` on its own python-can virtual bus object (the bus name is
shared with the bridge, so they hear each other): it broadcasts uavcan.protocol.NodeStatus at 1 Hz
(OPERATIONAL, healthy, its uptime), answers uavcan.protocol.GetNodeInfo (name, software and
hardware version, a unique id made from the bus and node id) and uavcan.protocol.param.GetSet
(by index or name; a write within the parameter's range is kept) and
uavcan.protocol.param.ExecuteOpcode (save / erase: accepted). Kinds:
- gps (node id 10, "org.gcsd.gps"): uavcan.equipment.gnss.Fix2 at 5 Hz with the vehicle's
  position, height, NED velocity and fix (from `state()`);
- battery (node id 11, "org.gcsd.battery"): uavcan.equipment.power.BatteryInfo at 1 Hz with the
  vehicle's voltage, current and state of charge.

pydronecan's own python-can driver is not used: it passes milliseconds where python-can expects
seconds (`PythonCAN.receive`), so a non-blocking spin would block; `_VirtualDriver` reads with timeout
0. `spin()` is called from the daemon's send passes; dronecan's scheduler keeps its own monotonic
time (a library's, at this I/O edge).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import can
import dronecan
from dronecan.driver.common import AbstractDriver, CANFrame

NODE_IDS = {"gps": 10, "battery": 11}
GPS_PERIOD_S = 0.2
BATTERY_PERIOD_S = 1.0
SOFTWARE_VERSION = (1, 0)
U = dronecan.uavcan


class _VirtualDriver(AbstractDriver):
    """A dronecan driver over one python-can bus object, never blocking."""

    def __init__(self, channel: str, interface: str = "virtual") -> None:
        super().__init__()
        self.bus = can.Bus(interface=interface, channel=channel, receive_own_messages=False)

    def send_frame(self, frame: CANFrame) -> None:
        self.bus.send(can.Message(arbitration_id=frame.id, is_extended_id=frame.extended, data=bytes(frame.data),
                                  is_fd=frame.canfd), timeout=0)
        self._tx_hook(frame)

    def receive(self, timeout=None):
        msg = self.bus.recv(0)
        if msg is None or msg.is_error_frame:
            return None
        frame = CANFrame(msg.arbitration_id, bytearray(msg.data), msg.is_extended_id, canfd=bool(msg.is_fd))
        self._rx_hook(frame)
        return frame

    def close(self) -> None:
        self.bus.shutdown()


class _Param:
    def __init__(self, name: str, value: float, lo: float, hi: float, integer: bool) -> None:
        self.name, self.value, self.default, self.lo, self.hi, self.integer = name, value, value, lo, hi, integer

    def value_msg(self, v: float):
        return U.protocol.param.Value(integer_value=int(v)) if self.integer else U.protocol.param.Value(real_value=v)

    def numeric(self, v: float):
        return U.protocol.param.NumericValue(integer_value=int(v)) if self.integer else \
            U.protocol.param.NumericValue(real_value=v)


PARAMS = {
    "gps": [("GPS_TYPE", 1, 0, 20, True), ("GPS_RATE_HZ", 5, 1, 20, True), ("GPS_MIN_ELEV", -100, -100, 90, True)],
    "battery": [("BATT_CAPACITY_MAH", 5000, 0, 100000, True), ("BATT_CELLS", 4, 1, 14, True),
                ("BATT_ARM_VOLT", 14.0, 0.0, 100.0, False)],
}


class SimNode:
    def __init__(self, kind: str, bus_index: int, channel: str, state: Callable[[], object]) -> None:
        self.kind = kind
        self.state = state
        node_id = NODE_IDS[kind]
        info = U.protocol.GetNodeInfo.Response()
        info.name = f"org.gcsd.{kind}"
        info.software_version.major, info.software_version.minor = SOFTWARE_VERSION
        info.hardware_version.major = 1
        info.hardware_version.unique_id = [bus_index, node_id] + [0x5A] * 14
        self.driver = _VirtualDriver(channel)
        self.node = dronecan.node.Node(self.driver, node_id=node_id, node_info=info,
                                       mode=U.protocol.NodeStatus().MODE_OPERATIONAL)
        self.params = [_Param(*p) for p in PARAMS[kind]]
        self.node.add_handler(U.protocol.param.GetSet, self._get_set)
        self.node.add_handler(U.protocol.param.ExecuteOpcode, self._opcode)
        if kind == "gps":
            self.node.periodic(GPS_PERIOD_S, self._publish_fix)
        else:
            self.node.periodic(BATTERY_PERIOD_S, self._publish_battery)

    def spin(self) -> None:
        self.node.spin(0)

    def close(self) -> None:
        self.node.close()

    # --- services ------------------------------------------------------------------------------
    def _find(self, request) -> _Param | None:
        name = bytes(request.name).decode(errors="replace")
        if name:
            return next((p for p in self.params if p.name == name), None)
        return self.params[request.index] if request.index < len(self.params) else None

    def _get_set(self, event):
        request = event.request
        param = self._find(request)
        response = U.protocol.param.GetSet.Response()
        if param is None:
            return response  # empty name: no such parameter
        which = dronecan.get_active_union_field(request.value)
        if which in ("integer_value", "real_value"):
            v = float(getattr(request.value, which))
            if math.isfinite(v) and param.lo <= v <= param.hi:
                param.value = int(v) if param.integer else v
        response.name = param.name
        response.value = param.value_msg(param.value)
        response.default_value = param.value_msg(param.default)
        response.min_value = param.numeric(param.lo)
        response.max_value = param.numeric(param.hi)
        return response

    def _opcode(self, event):
        return U.protocol.param.ExecuteOpcode.Response(ok=True)

    # --- publishers ------------------------------------------------------------------------------
    def _publish_fix(self) -> None:
        s = self.state()
        fix = U.equipment.gnss.Fix2()
        fix.latitude_deg_1e8 = round(s.lat * 1e8)
        fix.longitude_deg_1e8 = round(s.lon * 1e8)
        fix.height_msl_mm = round(s.alt_amsl_m * 1000)
        fix.height_ellipsoid_mm = fix.height_msl_mm
        fix.ned_velocity = [s.vn_ms, s.ve_ms, s.vd_ms]
        fix.sats_used = s.satellites
        fix.status = fix.STATUS_3D_FIX if s.gps_fix_type >= 3 else fix.STATUS_NO_FIX
        fix.pdop = s.hdop
        self.node.broadcast(fix)

    def _publish_battery(self) -> None:
        s = self.state()
        info = U.equipment.power.BatteryInfo()
        info.voltage = s.battery_voltage_v
        info.current = s.current_a
        info.state_of_charge_pct = s.battery_remaining_pct
        info.full_charge_capacity_wh = s.capacity_mah * 14.8 / 1000
        info.remaining_capacity_wh = info.full_charge_capacity_wh * s.battery_remaining_pct / 100
        info.model_name = "gcsd-sim"
        self.node.broadcast(info)
