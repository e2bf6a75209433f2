"""The composition root's hooks (compose.py): a service added to SERVICES gets its handlers,
its extra component (own compid, own command table, ACKs from it, local to the router) and its
tap on every accepted frame, with no other file touched."""

from __future__ import annotations

import yaml
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.clock import Clock
from gcsd.config import parse_config
from gcsd.daemon import compose
from gcsd.daemon.daemon import Daemon
from gcsd.vehicle.services import Service
from gcsd.wire.codec import FrameParser
from gcsd.wire.msgids import ACCEPTED

CAMERA = 100


class Probe(Service):
    """A service with a message handler, an extra component and a tap."""

    def __init__(self, ctx) -> None:
        self.ctx = ctx
        self.pings: list[int] = []
        self.tapped: list[str] = []
        self.shots = 0

    def handle_PING(self, inc) -> None:
        self.pings.append(inc.msg.seq)

    def local_components(self):
        return {CAMERA: {M.MAV_CMD_IMAGE_START_CAPTURE: self.shoot}}

    def shoot(self, req) -> int:
        self.shots += 1
        return ACCEPTED

    def tap(self, channel, frame, now) -> None:
        self.tapped.append(frame.name)


def _daemon(tmp_path, monkeypatch):
    monkeypatch.setattr(compose, "SERVICES", (*compose.SERVICES, ("probe", lambda node, w: Probe(node))))
    config = parse_config(yaml.safe_dump({"state_dir": str(tmp_path), "channels": [
        {"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]}), "t.yaml")
    t = [100.0]
    gcs = Daemon(config, Clock(monotonic=lambda: t[0], wall=lambda: 1.8e9))
    sent: list[bytes] = []
    channel = gcs.channels[0]
    peer = channel.add_peer("station", lambda data: sent.append(data) or True, 100.0)
    return gcs, channel, peer, sent


def _frames(*msgs) -> bytes:
    mav = M.MAVLink(None, srcSystem=255, srcComponent=190)
    return b"".join(bytes(m.pack(mav)) for m in msgs)


def test_a_service_in_services_gets_its_handler_its_component_and_its_tap(tmp_path, monkeypatch):
    gcs, channel, peer, sent = _daemon(tmp_path, monkeypatch)
    probe = next(s for s in gcs.nodes[0].services if isinstance(s, Probe))
    channel.receive(peer, _frames(
        M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3),
        M.MAVLink_ping_message(0, 7, 1, 1),
        M.MAVLink_command_long_message(1, CAMERA, M.MAV_CMD_IMAGE_START_CAPTURE, 0, 0, 0, 1, 0, 0, 0, 0),
    ), 100.0)
    assert probe.pings == [7]
    assert probe.shots == 1
    assert probe.tapped == ["HEARTBEAT", "PING", "COMMAND_LONG"]
    assert (1, CAMERA) in gcs.router.local
    acks = [f for f in FrameParser().feed(b"".join(sent)) if f.name == "COMMAND_ACK"]
    assert len(acks) == 1 and (acks[0].sysid, acks[0].compid) == (1, CAMERA)
    assert acks[0].msg.result == ACCEPTED
