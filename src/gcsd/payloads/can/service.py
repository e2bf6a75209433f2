"""CAN over MAVLink on the autopilot component (ArduPilot's AP_MAVLinkCAN), over python-can buses.

MAV_CMD_CAN_FORWARD (param1 = bus + 1, 0 stops; FAILED for a bus that is not configured) and
CAN_FILTER_MODIFY go to the `CanForwarder` core with the client's (channel, sysid, compid);
CAN_FRAME / CANFD_FRAME from a client are queued by the core (20 frames) and written to the bus
at once. Reading: at most every POLL_S, from a send pass, each bus is read without blocking (at
most POLL_LIMIT frames), the simulated DroneCAN nodes spin, and every frame goes to each client
that forwards its bus and passes its filter, as CAN_FRAME / CANFD_FRAME addressed to that client,
on that client's channel only (OUTBOX_MAX per channel; the oldest are dropped and counted). While
a client forwards, the service asks for a send pass every POLL_S; with none, every IDLE_POLL_S
(the simulated nodes keep their time). Clients stop 5 s after their last CAN_FORWARD (the core).
`shutdown` closes the buses and the nodes at a clean stop. Counters: frames in and out per bus,
write errors, inbound frames refused or dropped, outbox drops.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.config.can import CanConfig
from gcsd.payloads.can.buses import CanBus
from gcsd.payloads.can.forward import CanForwarder, Client, frame_message
from gcsd.payloads.can.nodes import SimNode
from gcsd.vehicle.services import Incoming, Service
from gcsd.vehicle.services.commands import CommandRequest

POLL_S = 0.01
IDLE_POLL_S = 0.1
POLL_LIMIT = 64
OUTBOX_MAX = 256


class CanService(Service):
    def __init__(self, ctx, config: CanConfig) -> None:
        self.ctx = ctx
        self.buses: list[CanBus] = []
        self.nodes: list[SimNode] = []
        try:
            for index, bus in enumerate(config.buses):
                self.buses.append(CanBus(index, bus))
                self.nodes += [SimNode(kind, index, bus.channel, lambda: ctx.state) for kind in bus.nodes]
        except Exception:
            self.shutdown(0.0)
            raise
        self.forwarder = CanForwarder(len(self.buses))
        self.outbox: dict[int, list] = {}
        self.outbox_dropped = 0
        self._polled_s: float | None = None
        self._closed = False

    def counters(self) -> dict[str, int]:
        fw = self.forwarder
        out = {"can_inbound_refused": fw.refused_inbound, "can_inbound_dropped": fw.dropped_inbound,
               "can_forwarded": fw.forwarded, "can_outbox_dropped": self.outbox_dropped}
        for bus in self.buses:
            out[f"can{bus.index}_frames_in"] = bus.frames_in
            out[f"can{bus.index}_frames_out"] = bus.frames_out
            out[f"can{bus.index}_write_errors"] = bus.write_errors
        return out

    def commands(self):
        return {M.MAV_CMD_CAN_FORWARD: self.can_forward}

    def _client(self, inc: Incoming) -> Client:
        return Client(inc.channel.index, *inc.sender)

    def can_forward(self, req: CommandRequest) -> int:
        result = self.forwarder.request(self._client(req.inc), req.param1, req.inc.now)
        self.ctx.wake(req.inc.channel)
        return result

    # --- messages ------------------------------------------------------------------------------
    def handle_CAN_FRAME(self, inc: Incoming) -> None:
        self._from_client(inc, fd=False)

    def handle_CANFD_FRAME(self, inc: Incoming) -> None:
        self._from_client(inc, fd=True)

    def _from_client(self, inc: Incoming, fd: bool) -> None:
        m = inc.msg
        if self.forwarder.from_client(m.bus, m.len, m.id, bytes(m.data), fd):
            self._write()

    def handle_CAN_FILTER_MODIFY(self, inc: Incoming) -> None:
        m = inc.msg
        if m.num_ids <= len(m.ids):  # a count beyond the array is refused, as ArduPilot
            self.forwarder.filter_modify(self._client(inc), m.bus, m.operation, list(m.ids[:m.num_ids]))

    # --- the buses -------------------------------------------------------------------------------
    def _write(self) -> None:
        for frame in self.forwarder.take():
            self.buses[frame.bus].send(frame)

    def _poll(self, now: float) -> None:
        if self._closed or (self._polled_s is not None and now - self._polled_s < POLL_S):
            return
        self._polled_s = now
        for sim in self.nodes:
            sim.spin()
        self._write()
        channels = self.ctx.channels
        for bus in self.buses:
            for frame in bus.poll(POLL_LIMIT):
                for client in self.forwarder.from_bus(frame, now):
                    box = self.outbox.setdefault(client.channel, [])
                    box.append(frame_message(frame, client))
                    if len(box) > OUTBOX_MAX:
                        del box[0]
                        self.outbox_dropped += 1
        self.forwarder.expire(now)
        for index in self.outbox:
            self.ctx.wake(channels[index])

    def pending(self, channel, now: float, send) -> float | None:
        self._poll(now)
        for msg in self.outbox.pop(channel.index, []):
            send(msg)
        if self._closed or not (self.buses or self.nodes):
            return None
        return now + (POLL_S if self.forwarder.clients else IDLE_POLL_S)

    def shutdown(self, now: float) -> None:
        self._closed = True
        for sim in self.nodes:
            sim.close()
        for bus in self.buses:
            bus.close()
