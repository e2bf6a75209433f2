"""Who gets which CAN bus over MAVLink: AP_MAVLinkCAN's rules, for several clients at once. Pure.

States, per client (the channel, sysid and compid a MAV_CMD_CAN_FORWARD came from): not
forwarding, or forwarding one bus since its last request (`last_request_s`), with an optional
filter of DroneCAN message ids. Transitions:
- CAN_FORWARD param1 = bus + 1: start (or move to) that bus, refresh its timer; ACCEPTED. A bus
  that does not exist: FAILED, nothing changes. param1 = 0: this client stops; ACCEPTED.
- No CAN_FORWARD for FORWARD_TIMEOUT_S: the client stops (ArduPilot checks every 100 frames;
  gcsd on every frame and at `expire(now)`, so the 5 s are exact).
- CAN_FILTER_MODIFY (bus 1-based, as ArduPilot and pydronecan): REPLACE (0 ids: no filter), ADD,
  REMOVE the client's sorted id set (at most 16 per message). A filtered frame passes when its
  DroneCAN id is in the set: anonymous frames (source node 0) have id 0, service frames (bit 7)
  bits 16-23, message frames bits 8-23.
Better than ArduPilot: every client that asks gets the bus (ArduPilot serves the last one only),
each with its own filter, and at most MAX_CLIENTS at once (the longest silent is dropped).

Inbound CAN_FRAME / CANFD_FRAME (bus 0-based) for an existing bus are queued, at most
INBOUND_BUFFER frames (ArduPilot's 20; a full buffer drops the new frame and counts it); `take()`
hands them to the bus writer. `len` above the frame's limit (8, or 64 for CAN FD) is refused.
CAN ids carry bit 31 for an extended (29-bit) id, as on the wire of both messages.
"""

from __future__ import annotations

import bisect
from collections import deque
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as M

FORWARD_TIMEOUT_S = 5.0
INBOUND_BUFFER = 20
MAX_CLIENTS = 8
EXTENDED_FLAG = 1 << 31
CAN_MAX_LEN, CANFD_MAX_LEN = 8, 64
FILTER_MAX_IDS = 16


@dataclass(frozen=True, slots=True)
class Client:
    channel: int
    sysid: int
    compid: int


@dataclass(frozen=True, slots=True)
class CanFrame:
    bus: int  # 0-based
    can_id: int  # 29 or 11 bits, plus EXTENDED_FLAG
    data: bytes
    fd: bool = False


@dataclass(slots=True)
class _Forwarding:
    bus: int
    last_request_s: float
    ids: list[int] = field(default_factory=list)  # sorted; empty: no filter


def dronecan_id(can_id: int) -> int:
    """The DroneCAN data type id a filter compares (AP_MAVLinkCAN::can_frame_callback)."""
    if can_id & 0xFF == 0:
        return 0  # anonymous
    if can_id & 0x80:
        return (can_id >> 16) & 0xFF  # service
    return (can_id >> 8) & 0xFFFF  # message


class CanForwarder:
    def __init__(self, bus_count: int) -> None:
        self.bus_count = bus_count
        self.clients: dict[Client, _Forwarding] = {}
        self.inbound: deque[CanFrame] = deque()
        self.dropped_inbound = 0
        self.refused_inbound = 0
        self.forwarded = 0

    def has_bus(self, bus: int) -> bool:
        return 0 <= bus < self.bus_count

    # --- requests ------------------------------------------------------------------------------
    def request(self, client: Client, param1: float, now: float) -> int:
        """MAV_CMD_CAN_FORWARD: the MAV_RESULT."""
        bus = int(param1) - 1
        if bus == -1:
            self.clients.pop(client, None)
            return M.MAV_RESULT_ACCEPTED
        if not self.has_bus(bus):
            return M.MAV_RESULT_FAILED
        state = self.clients.get(client)
        if state is None:
            if len(self.clients) >= MAX_CLIENTS:
                oldest = min(self.clients, key=lambda c: self.clients[c].last_request_s)
                del self.clients[oldest]
            self.clients[client] = _Forwarding(bus, now)
        else:
            state.bus, state.last_request_s = bus, now
        return M.MAV_RESULT_ACCEPTED

    def filter_modify(self, client: Client, bus_1based: int, operation: int, ids: list[int]) -> bool:
        """CAN_FILTER_MODIFY: True when the client's filter changed."""
        state = self.clients.get(client)
        if state is None or state.bus != bus_1based - 1 or len(ids) > FILTER_MAX_IDS:
            return False
        wanted = sorted(set(ids))
        before = list(state.ids)
        if operation == M.CAN_FILTER_REPLACE:
            state.ids = wanted
        elif operation == M.CAN_FILTER_ADD:
            state.ids = sorted(set(state.ids) | set(wanted))
        elif operation == M.CAN_FILTER_REMOVE:
            state.ids = [i for i in state.ids if i not in set(wanted)]
        else:
            return False
        return state.ids != before

    def expire(self, now: float) -> list[Client]:
        """Stop the clients that have not asked for FORWARD_TIMEOUT_S."""
        gone = [c for c, s in self.clients.items() if now - s.last_request_s > FORWARD_TIMEOUT_S]
        for c in gone:
            del self.clients[c]
        return gone

    def next_deadline(self) -> float | None:
        if not self.clients:
            return None
        return min(s.last_request_s for s in self.clients.values()) + FORWARD_TIMEOUT_S

    # --- frames ----------------------------------------------------------------------------------
    def from_bus(self, frame: CanFrame, now: float) -> list[Client]:
        """A frame seen on a bus: the clients it goes to (as CAN_FRAME or CANFD_FRAME)."""
        self.expire(now)
        out = []
        ident = None
        for client, state in self.clients.items():
            if state.bus != frame.bus:
                continue
            if state.ids:
                if ident is None:
                    ident = dronecan_id(frame.can_id)
                i = bisect.bisect_left(state.ids, ident)
                if i == len(state.ids) or state.ids[i] != ident:
                    continue
            out.append(client)
        self.forwarded += len(out)
        return out

    def from_client(self, bus: int, length: int, can_id: int, data: bytes, fd: bool) -> bool:
        """CAN_FRAME / CANFD_FRAME from a ground station: queued for the bus (False: refused or dropped)."""
        if not self.has_bus(bus) or length > (CANFD_MAX_LEN if fd else CAN_MAX_LEN):
            self.refused_inbound += 1
            return False
        if len(self.inbound) >= INBOUND_BUFFER:
            self.dropped_inbound += 1
            return False
        self.inbound.append(CanFrame(bus, can_id, bytes(data[:length]), fd))
        return True

    def take(self) -> list[CanFrame]:
        frames = list(self.inbound)
        self.inbound.clear()
        return frames


def frame_message(frame: CanFrame, client: Client):
    """The CAN_FRAME or CANFD_FRAME that carries `frame` to `client`."""
    size = CANFD_MAX_LEN if frame.fd else CAN_MAX_LEN
    data = frame.data.ljust(size, b"\0")
    cls = M.MAVLink_canfd_frame_message if frame.fd else M.MAVLink_can_frame_message
    return cls(client.sysid, client.compid, frame.bus, len(frame.data), frame.can_id, data)
