"""A vehicle node with a float clock and one in-memory channel: the unit-test harness.

`Harness(tmp_path, vehicle="copter", config={...})` builds the real vehicle node with the
composition root (parameters, services, autopilot, simulation) from YAML-equivalent configuration, with a Clock whose `now`
is a float the test advances. Messages from the "ground station" (sysid 255) go in through the
node's dispatch (`send`, `command`); everything the node sends on the channel is decoded with
pymavlink and kept (`received`, `texts()`, `last(type)`). `run(seconds)` advances the clock in
steps, stepping the simulation (`node.step`) and running the node's send pass each time;
`serve(seconds)` instead runs each pass at the deadline the previous one returned, as the
channel task does (what a test of the byte budget's pacing needs).
"""

from __future__ import annotations

import yaml
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.boundary import ErrorCounts
from gcsd.clock import Clock
from gcsd.config import parse_config
from gcsd.daemon.compose import build_vehicle
from gcsd.links.channel import Channel
from gcsd.wire.codec import Frame
from gcsd.wire.signing import SigningManager

GCS = (255, 190)


class Harness:
    def __init__(self, tmp_path, vehicle: str = "copter", config: dict | None = None, backend=None) -> None:
        self.t = 1000.0
        data = {"vehicle": {"type": vehicle}, "state_dir": str(tmp_path / "state"),
                "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]}
        for key, value in (config or {}).items():
            if isinstance(value, dict) and isinstance(data.get(key), dict):
                data[key] = {**data[key], **value}
            else:
                data[key] = value
        self.config = parse_config(yaml.safe_dump(data), "harness.yaml")
        self.clock = Clock(monotonic=lambda: self.t, wall=lambda: 1.8e9 + self.t)
        self.channel = Channel(0, self.config.channels[0], self.clock.now)
        self.received: list = []
        self._parser = M.MAVLink(None)
        self._parser.robust_parsing = True
        self.channel.add_peer("gcs", self._write)
        self.node = build_vehicle(0, self.config, self.clock, [self.channel], lambda ch: None, ErrorCounts(),
                                  SigningManager(None, False, None, self.clock.wall()), backend=backend)
        self._out = M.MAVLink(None, srcSystem=GCS[0], srcComponent=GCS[1])

    def _write(self, data: bytes) -> bool:
        for msg in self._parser.parse_buffer(data) or []:
            if msg.get_type() != "BAD_DATA":
                self.received.append(msg)
        return True

    @property
    def state(self):
        return self.node.state

    # --- in ------------------------------------------------------------------------------------
    def send(self, msg, sysid: int = GCS[0], compid: int = GCS[1]) -> None:
        self._out.srcSystem, self._out.srcComponent = sysid, compid
        msg.pack(self._out)
        self.channel.tick(self.t, self.clock.wall())  # as the transport does at each wake-up
        self.node.handle(self.channel, Frame.from_message(msg), self.t)
        self.node.send_pass(self.channel, self.t)  # what it queued (STATUSTEXT...) goes out now

    def command(self, command: int, *params: float, sysid: int = GCS[0]) -> int | None:
        p = list(params) + [0.0] * (7 - len(params))
        mark = len(self.received)
        self.send(M.MAVLink_command_long_message(self.node.sysid, 1, command, 0, *p), sysid=sysid)
        return self._ack(command, mark)

    def command_int(self, command: int, p1=0.0, p2=0.0, p3=0.0, p4=0.0, x=0, y=0, z=0.0,
                    frame: int = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT) -> int | None:
        mark = len(self.received)
        self.send(M.MAVLink_command_int_message(self.node.sysid, 1, frame, command, 0, 0, p1, p2, p3, p4, x, y, z))
        return self._ack(command, mark)

    def _ack(self, command: int, mark: int) -> int | None:
        acks = [m for m in self.received[mark:] if m.get_type() == "COMMAND_ACK" and m.command == command]
        return acks[0].result if acks else None

    def mode(self, name: str) -> int | None:
        number = self.node.vehicle.mode_number(name)
        return self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, number)

    def arm(self, force: bool = False) -> int | None:
        return self.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, 21196 if force else 0)

    def set_param(self, name: str, value: float) -> None:
        self.send(M.MAVLink_param_set_message(self.node.sysid, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32))

    # --- time ----------------------------------------------------------------------------------
    def run(self, seconds: float, step: float = 0.05, until=None) -> bool:
        """Advance the clock; with `until`, stop as soon as until() is true (returns whether it was)."""
        end = self.t + seconds
        while self.t < end:
            self.t = min(end, self.t + step)
            self.node.step(self.t)  # the simulation task's tick
            self.channel.tick(self.t, self.clock.wall())
            self.node.send_pass(self.channel, self.t)
            if until is not None and until():
                return True
        return until is None

    def serve(self, seconds: float, until=None, sim_step: float = 0.05) -> bool:
        """Advance the clock as the channel task does (transport.run_channel): the next send pass
        at the deadline the last one returned (at most 0.5 s later), the simulation every
        sim_step; with `until`, stop as soon as until() is true (returns whether it was)."""
        end = self.t + seconds
        deadline, next_step = self.t, self.t
        while self.t < end:
            wake = self.t + 0.5 if deadline is None else min(max(deadline, self.t + 1e-4), self.t + 0.5)
            self.t = min(wake, next_step, end)
            if self.t >= next_step:
                self.node.step(self.t)
                next_step = self.t + sim_step
            self.channel.tick(self.t, self.clock.wall())
            deadline = self.node.send_pass(self.channel, self.t)
            if until is not None and until():
                return True
        return until is None

    # --- out -----------------------------------------------------------------------------------
    def texts(self, since: int = 0) -> list[str]:
        return [m.text for m in self.received[since:] if m.get_type() == "STATUSTEXT"]

    def of_type(self, name: str, since: int = 0) -> list:
        return [m for m in self.received[since:] if m.get_type() == name]

    def mark(self) -> int:
        return len(self.received)
