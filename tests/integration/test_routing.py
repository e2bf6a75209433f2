"""Routing between channels, as REFERENCE.md section 3 (ArduPilot's MAVLink_routing) and SPEC.md say.

Three udp-server channels: `gcs1` with a ground station (255, 190), `gcs2` with a ground station
(254, 190), and `cam` with a camera (1, 100) of the vehicle's own system (the vehicle is 1/1).
Everyone heartbeats first so routes are learned; then each test sends one frame and checks who
received it, and that forwarded frames are the very bytes that were sent.
"""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from .helpers import (
    M, VEHICLE, Client, Received, from_vehicle, is_ack, pump, udp_channel, udp_url, v2_frame, wait_for,
)

GCS1 = (255, 190)
GCS2 = (254, 190)
CAM = (1, 100)
SETTLE_S = 0.3  # long enough for a forwarded frame on loopback; silence is checked over this


@dataclass
class Net:
    d: object
    gcs1: Client
    gcs2: Client
    cam: Client

    @property
    def all(self) -> list[Client]:
        return [self.gcs1, self.gcs2, self.cam]

    def marks(self) -> dict[str, int]:
        return {"gcs1": self.gcs1.mark(), "gcs2": self.gcs2.mark(), "cam": self.cam.mark()}

    def after(self, raw: bytes, seconds: float = SETTLE_S) -> dict[str, list[Received]]:
        """Read for a while; which clients received a frame with exactly these bytes."""
        marks = self.marks()
        pump(self.all, seconds)
        return {
            name: [r for r in getattr(self, name).since(mark) if r.raw == raw]
            for name, mark in marks.items()
        }


def _start(daemon, client, cam_extra: dict | None = None) -> Net:
    cam = udp_channel("cam", **(cam_extra or {}))
    d = daemon({"channels": [udp_channel("gcs1"), udp_channel("gcs2"), cam]})
    net = Net(
        d,
        client(udp_url(d.port("gcs1")), *GCS1),
        client(udp_url(d.port("gcs2")), *GCS2),
        client(udp_url(d.port("cam")), *CAM),
    )
    for c in net.all:
        c.heartbeat(M.MAV_TYPE_CAMERA if c is net.cam else M.MAV_TYPE_GCS)
    for c in net.all:  # the vehicle talks only to peers it has heard: every route is learned now
        assert wait_for(c, from_vehicle, others=net.all), "nothing from the vehicle"
    return net


@pytest.fixture
def net(daemon, client) -> Net:
    return _start(daemon, client)


@pytest.fixture
def private_cam(daemon, client) -> Net:
    return _start(daemon, client, {"private": True})


@pytest.fixture
def no_forward_cam(daemon, client) -> Net:
    return _start(daemon, client, {"options": ["no_forward"]})


def _command(target: tuple[int, int], command: int = M.MAV_CMD_GET_MESSAGE_INTERVAL,
             param1: float = M.MAVLINK_MSG_ID_ATTITUDE):
    return M.MAVLink_command_long_message(target[0], target[1], command, 0, param1, 0, 0, 0, 0, 0, 0)


def _acks(c: Client, mark: int, command: int) -> list[Received]:
    return [r for r in c.since(mark, "COMMAND_ACK") if r.src == VEHICLE and r.msg.command == command]


# --- plain channels -------------------------------------------------------------------------

def test_command_targeted_at_camera_reaches_only_the_camera_channel(net):
    raw = net.gcs1.send(_command(CAM))
    got = net.after(raw, 1.0)
    assert len(got["cam"]) == 1
    assert got["gcs2"] == []
    assert got["gcs1"] == []


def test_vehicle_does_not_answer_a_command_for_another_component_of_its_system(net):
    mark = net.gcs1.mark()
    net.gcs1.send(_command(CAM))
    pump(net.all, 1.0)
    assert _acks(net.gcs1, mark, M.MAV_CMD_GET_MESSAGE_INTERVAL) == []
    assert net.gcs1.since(mark, "MESSAGE_INTERVAL") == []


def test_broadcast_reaches_every_other_channel_and_is_processed(net):
    mark = net.gcs1.mark()
    raw = net.gcs1.send(_command((0, 0)))
    got = net.after(raw)
    assert len(got["gcs2"]) == 1
    assert len(got["cam"]) == 1
    assert got["gcs1"] == []
    assert len(_acks(net.gcs1, mark, M.MAV_CMD_GET_MESSAGE_INTERVAL)) == 1


def test_param_request_list_broadcast_reaches_every_other_channel(net):
    raw = net.gcs1.send(M.MAVLink_param_request_list_message(0, 0))
    got = net.after(raw)
    assert (len(got["gcs2"]), len(got["cam"]), len(got["gcs1"])) == (1, 1, 0)


def test_message_to_our_system_any_component_is_processed_and_copied_to_the_camera(net):
    mark = net.gcs1.mark()
    raw = net.gcs1.send(_command((1, 0)))
    got = net.after(raw)
    assert len(got["cam"]) == 1
    assert got["gcs2"] == []
    assert got["gcs1"] == []
    acks = _acks(net.gcs1, mark, M.MAV_CMD_GET_MESSAGE_INTERVAL)
    assert [a.msg.result for a in acks] == [M.MAV_RESULT_ACCEPTED]


def test_message_for_the_vehicle_itself_is_processed_and_not_forwarded(net):
    mark = net.gcs1.mark()
    raw = net.gcs1.send(_command(VEHICLE))
    got = net.after(raw)
    assert got == {"gcs1": [], "gcs2": [], "cam": []}
    assert len(_acks(net.gcs1, mark, M.MAV_CMD_GET_MESSAGE_INTERVAL)) == 1


def test_message_for_an_unknown_system_is_dropped(net):
    mark = net.gcs1.mark()
    raw = net.gcs1.send(_command((77, 1)))
    got = net.after(raw)
    assert got == {"gcs1": [], "gcs2": [], "cam": []}
    assert _acks(net.gcs1, mark, M.MAV_CMD_GET_MESSAGE_INTERVAL) == []


def test_heartbeat_is_forwarded_to_every_other_channel_never_back(net):
    raw = net.gcs1.heartbeat()
    got = net.after(raw)
    assert len(got["gcs2"]) == 1
    assert len(got["cam"]) == 1
    assert got["gcs1"] == []


def test_nothing_from_a_ground_station_ever_comes_back_to_it(net):
    mark = net.gcs1.mark()
    net.gcs1.heartbeat()
    net.gcs1.send(_command((0, 0)))
    net.gcs1.send(_command(CAM))
    net.gcs1.send(_command((1, 0)))
    net.gcs1.send(M.MAVLink_param_request_list_message(0, 0))
    pump(net.all, SETTLE_S)
    assert [r for r in net.gcs1.since(mark) if r.src == GCS1] == []


def test_camera_reply_targeted_at_a_ground_station_reaches_only_that_ground_station(net):
    ack = M.MAVLink_command_ack_message(M.MAV_CMD_IMAGE_START_CAPTURE, M.MAV_RESULT_ACCEPTED, 0, 0, *GCS1)
    raw = net.cam.send(ack)
    got = net.after(raw)
    assert len(got["gcs1"]) == 1
    assert got["gcs2"] == []
    assert got["cam"] == []


def test_forwarded_frames_are_byte_identical(net):
    raw = net.gcs1.send(_command(CAM, M.MAV_CMD_IMAGE_START_CAPTURE, 0))
    got = net.after(raw)
    (r,) = got["cam"]
    assert r.raw == raw
    assert (r.msg.get_seq(), r.src, r.msg.command) == (raw[4], GCS1, M.MAV_CMD_IMAGE_START_CAPTURE)


def test_unknown_message_id_is_forwarded_unchanged_as_a_broadcast(net):
    raw = v2_frame(42424, bytes(range(20)), *GCS1, seq=7, crc=b"\xab\xcd")
    net.gcs1.write(raw)
    got = net.after(raw)
    assert len(got["gcs2"]) == 1
    assert len(got["cam"]) == 1
    assert got["gcs1"] == []
    assert got["gcs2"][0].type == "UNKNOWN_42424"


def test_unknown_message_id_from_a_source_never_seen_with_a_good_frame_is_dropped(net):
    raw = v2_frame(42424, bytes(range(20)), 99, 1)  # its CRC cannot be checked: it could be noise
    net.gcs1.write(raw)
    got = net.after(raw)
    assert got == {"gcs1": [], "gcs2": [], "cam": []}


def test_twenty_five_systems_heartbeating_through_one_channel_do_not_break_routing(net, client):
    swarm_sysids = range(100, 125)
    swarm = client(udp_url(net.d.port("gcs2")), 100, 1)
    senders = {s: M.MAVLink(swarm.conn, srcSystem=s, srcComponent=1) for s in swarm_sysids}
    for _ in range(3):
        for mav in senders.values():
            mav.heartbeat_send(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0)
        pump([*net.all, swarm], 0.2)
    pump([*net.all, swarm], SETTLE_S)
    seen_by_gcs1 = {r.src[0] for r in net.gcs1.received if r.type == "HEARTBEAT"}
    assert set(swarm_sysids) <= seen_by_gcs1

    # the routes learned before the swarm arrived still work, both ways, and the vehicle answers
    got = net.after(net.gcs1.send(_command(CAM)))
    assert (len(got["cam"]), len(got["gcs2"])) == (1, 0)
    ack = M.MAVLink_command_ack_message(M.MAV_CMD_IMAGE_START_CAPTURE, M.MAV_RESULT_ACCEPTED, 0, 0, *GCS1)
    got = net.after(net.cam.send(ack))
    assert (len(got["gcs1"]), len(got["gcs2"])) == (1, 0)
    mark = net.gcs1.mark()
    got = net.after(net.gcs1.send(_command((0, 0))))
    assert (len(got["gcs2"]), len(got["cam"])) == (1, 1)
    assert len(_acks(net.gcs1, mark, M.MAV_CMD_GET_MESSAGE_INTERVAL)) == 1
    mark = net.gcs2.mark()
    net.gcs2.send(_command(VEHICLE))
    assert wait_for(net.gcs2, is_ack(M.MAV_CMD_GET_MESSAGE_INTERVAL), since=mark, others=net.all)


# --- a private channel ----------------------------------------------------------------------

def test_private_channel_gets_no_forwarded_broadcasts(private_cam):
    net = private_cam
    raw = net.gcs1.send(_command((0, 0)))
    got = net.after(raw)
    assert len(got["gcs2"]) == 1
    assert got["cam"] == []
    unknown = v2_frame(42424, bytes(8), *GCS1)
    net.gcs1.write(unknown)
    got = net.after(unknown)
    assert len(got["gcs2"]) == 1
    assert got["cam"] == []


def test_private_channel_gets_no_forwarded_heartbeats(private_cam):
    net = private_cam
    raw = net.gcs1.heartbeat()
    got = net.after(raw)
    assert len(got["gcs2"]) == 1
    assert got["cam"] == []
    assert [r for r in net.cam.received if r.type == "HEARTBEAT" and r.src != VEHICLE] == []


def test_private_channel_gets_frames_addressed_exactly_to_a_node_on_it(private_cam):
    net = private_cam
    raw = net.gcs1.send(_command(CAM))
    got = net.after(raw)
    assert len(got["cam"]) == 1
    assert got["gcs2"] == []


def test_private_channel_still_gets_the_vehicle_telemetry(private_cam):
    net = private_cam
    mark = net.cam.mark()
    pump(net.all, 1.2)
    assert net.cam.since(mark, "HEARTBEAT")[0].src == VEHICLE
    assert [r for r in net.cam.since(mark, "ATTITUDE") if r.src == VEHICLE]


def test_nothing_received_on_a_private_channel_is_forwarded(private_cam):
    net = private_cam
    sent = [
        net.cam.heartbeat(M.MAV_TYPE_CAMERA),
        net.cam.send(M.MAVLink_command_ack_message(M.MAV_CMD_IMAGE_START_CAPTURE, 0, 0, 0, *GCS1)),
        net.cam.send(_command((0, 0), M.MAV_CMD_IMAGE_STOP_CAPTURE, 0)),
        net.cam.send(_command(GCS2, M.MAV_CMD_IMAGE_STOP_CAPTURE, 0)),
    ]
    unknown = v2_frame(42424, bytes(8), *CAM)
    net.cam.write(unknown)
    pump(net.all, SETTLE_S)
    for c in (net.gcs1, net.gcs2):
        assert [r for r in c.received if r.raw in (*sent, unknown)] == []
        assert [r for r in c.received if r.src == CAM] == []


def test_private_channel_peer_is_still_served_by_the_vehicle(private_cam):
    net = private_cam
    mark = net.cam.mark()
    net.cam.send(_command(VEHICLE))
    ack = wait_for(net.cam, is_ack(M.MAV_CMD_GET_MESSAGE_INTERVAL), since=mark, others=net.all)
    assert ack is not None and ack.msg.result == M.MAV_RESULT_ACCEPTED


# --- a no_forward channel -------------------------------------------------------------------

def test_no_forward_channel_gets_no_forwarded_frames_at_all(no_forward_cam):
    net = no_forward_cam
    sent = [
        net.gcs1.heartbeat(),
        net.gcs1.send(_command((0, 0))),
        net.gcs1.send(_command((1, 0))),
        net.gcs1.send(_command(CAM)),
    ]
    unknown = v2_frame(42424, bytes(8), *GCS1)
    net.gcs1.write(unknown)
    pump(net.all, SETTLE_S)
    assert [r for r in net.cam.received if r.src != VEHICLE] == []
    assert len([r for r in net.gcs2.received if r.raw in (sent[0], sent[1], unknown)]) == 3


def test_nothing_received_on_a_no_forward_channel_is_forwarded(no_forward_cam):
    net = no_forward_cam
    net.cam.heartbeat(M.MAV_TYPE_CAMERA)
    net.cam.send(M.MAVLink_command_ack_message(M.MAV_CMD_IMAGE_START_CAPTURE, 0, 0, 0, *GCS1))
    net.cam.send(_command((0, 0), M.MAV_CMD_IMAGE_STOP_CAPTURE, 0))
    net.cam.write(v2_frame(42424, bytes(8), *CAM))
    pump(net.all, SETTLE_S)
    for c in (net.gcs1, net.gcs2):
        assert [r for r in c.received if r.src == CAM] == []


def test_no_forward_channel_peer_is_still_served_by_the_vehicle(no_forward_cam):
    net = no_forward_cam
    mark = net.cam.mark()
    net.cam.send(_command(VEHICLE))
    ack = wait_for(net.cam, is_ack(M.MAV_CMD_GET_MESSAGE_INTERVAL), since=mark, others=net.all)
    assert ack is not None and ack.msg.result == M.MAV_RESULT_ACCEPTED
