"""Wiring of the flight logs (compose.SERVICES' "logs"): every vehicle serves its directory, the
simulated one writes while armed, and only a capturing vehicle has a tap (a tap costs every frame
of every channel: a swarm of non-capturing vehicles pays nothing)."""

from __future__ import annotations

import yaml
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.boundary import ErrorCounts
from gcsd.clock import Clock
from gcsd.config import parse_config
from gcsd.daemon.compose import build_vehicle
from gcsd.links.channel import Channel
from gcsd.payloads.logs.capture import SEQ_START
from gcsd.wire.codec import Frame
from gcsd.wire.signing import SigningManager


class Wire:
    """What the channel's peers would receive: the frames a service sends."""

    def __init__(self) -> None:
        self.frames: list[bytes] = []

    def __call__(self, data: bytes) -> bool:
        self.frames.append(data)
        return True


def build(tmp_path, vehicle: str, flight_logs: dict | None = None):
    config = parse_config(yaml.safe_dump({
        "vehicle": {"type": vehicle}, "state_dir": str(tmp_path / vehicle),
        "channels": [{"name": "fc", "type": "udp-server", "address": "127.0.0.1:0"}],
        "flight_logs": flight_logs or {}}), "t.yaml")
    clock = Clock(monotonic=lambda: 100.0, wall=lambda: 1.8e9)
    channel = Channel(0, config.channels[0], clock.now)
    wire = Wire()
    channel.add_peer(("127.0.0.1", 5760), wire, 100.0)
    node = build_vehicle(0, config, clock, [channel], lambda ch: None, ErrorCounts(),
                         SigningManager(None, False, None, clock.wall()))
    logs = next(s for s in node.services if type(s).__name__ == "FlightLogService")
    return node, logs, channel, wire


def test_a_vehicle_serves_logs_and_only_a_capturing_one_taps_frames(tmp_path):
    _, copter_logs, _, _ = build(tmp_path, "copter")
    assert copter_logs.recorder is not None and not hasattr(copter_logs, "tap")
    _, companion_logs, _, _ = build(tmp_path, "companion", {"capture": True})
    assert companion_logs.recorder is None and hasattr(companion_logs, "tap")


def test_the_tap_answers_a_flight_controllers_heartbeat_with_a_start(tmp_path):
    node, logs, channel, wire = build(tmp_path, "companion", {"capture": True})
    fc = M.MAVLink(None, srcSystem=1, srcComponent=1)
    beat = M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 3, 3)
    beat.pack(fc)
    logs.tap(channel, Frame.from_message(beat), 100.0)
    [raw] = wire.frames
    msg = M.MAVLink(None).parse_buffer(raw)[0]
    assert (msg.get_type(), msg.seqno, msg.target_system, msg.target_component) == (
        "REMOTE_LOG_BLOCK_STATUS", SEQ_START, 1, 1)
    assert (msg.get_srcSystem(), msg.get_srcComponent()) == (node.sysid, node.compid)



def test_simulated_false_leaves_the_simulated_vehicle_without_a_log(tmp_path):
    _, logs, _, _ = build(tmp_path, "copter", {"simulated": False})
    assert logs.recorder is None and not hasattr(logs, "tap")
