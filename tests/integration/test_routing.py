"""Routing between channels, as REFERENCE.md section 3 (ArduPilot's MAVLink_routing) and SPEC.md say.

Three udp-server channels: `gcs1` with a ground station (255, 190), `gcs2` with a ground station
(254, 190), and `cam` with a camera (1, 100) of the vehicle's own system (the vehicle is 1/1).
Everyone heartbeats first so routes are learned; then each test sends one frame and checks who
received it, and that forwarded frames are the very bytes that were sent.

Silence is never checked over a fixed window. After the frame under test, the same client sends a
barrier through the same socket (`Net.after`): a PARAM_SET to the vehicle, whose PARAM_VALUE the
vehicle sends on every non-private channel; a REQUEST_MESSAGE, whose COMMAND_ACK comes back to the
sender; and, when the camera's channel is private, a command addressed exactly to the camera.
The daemon reads one socket in order and forwards a frame before it handles the next, and each
channel writes to a client through one socket, so once every client has its part of the barrier,
anything the frame under test caused has arrived too. A stalled or dead daemon fails the barrier
instead of passing the "nothing arrived" check.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from gcsd.api import control

from .helpers import (
    VEHICLE,
    Client,
    M,
    Received,
    from_vehicle,
    is_ack,
    udp_channel,
    udp_url,
    v2_frame,
    wait_for,
)

GCS1 = (255, 190)
GCS2 = (254, 190)
CAM = (1, 100)
BARRIER_PARAM = b"BATT_ARM_VOLT"  # REAL32 0..100 V; only the arming checks read it
MAX_ROUTES = 20  # SPEC.md / REFERENCE.md section 3: the route table holds 20 (sysid, compid, channel)


@dataclass
class Net:
    d: object
    gcs1: Client
    gcs2: Client
    cam: Client
    cam_private: bool = False
    _barriers: itertools.count = field(default_factory=lambda: itertools.count(1))

    @property
    def all(self) -> list[Client]:
        return [self.gcs1, self.gcs2, self.cam]

    def names(self) -> dict[str, Client]:
        return {"gcs1": self.gcs1, "gcs2": self.gcs2, "cam": self.cam}

    def barrier(self, sender: Client) -> None:
        """Send a barrier from `sender` and wait until every client has its part (see the docstring)."""
        n = next(self._barriers)
        marks = {c: c.mark() for c in self.all}
        expect: dict[Client, object] = {}
        value = n / 8.0  # exact in a float32
        sender.send(M.MAVLink_param_set_message(*VEHICLE, BARRIER_PARAM, value, M.MAV_PARAM_TYPE_REAL32))
        for c in self.all:
            if not (c is self.cam and self.cam_private):
                expect[c] = lambda r, v=value: (r.type == "PARAM_VALUE" and r.src == VEHICLE
                                                and r.msg.param_id == BARRIER_PARAM.decode() and r.msg.param_value == v)
        sender.send(M.MAVLink_command_long_message(*VEHICLE, M.MAV_CMD_REQUEST_MESSAGE, 0,
                                                   M.MAVLINK_MSG_ID_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_SYS_STATUS,
                                                   0, 0, 0, 0, 0))
        expect[sender] = is_ack(M.MAV_CMD_REQUEST_MESSAGE)
        if self.cam_private and sender is not self.cam:
            raw = sender.send(_command(CAM, M.MAV_CMD_IMAGE_STOP_CAPTURE, float(n)))
            expect[self.cam] = lambda r, raw=raw: r.raw == raw
        for c, match in expect.items():
            assert wait_for(c, match, since=marks[c], others=self.all), \
                f"barrier {n} from {sender.sysid}/{sender.compid} never reached {c.sysid}/{c.compid}: daemon stalled?"

    def after(self, raw: bytes, sender: Client) -> dict[str, list[Received]]:
        """Which clients received a frame with exactly these bytes, sent just before by `sender`."""
        marks = {name: c.mark() for name, c in self.names().items()}
        self.barrier(sender)
        return {name: [r for r in c.since(marks[name]) if r.raw == raw] for name, c in self.names().items()}


def _start(daemon, client, cam_extra: dict | None = None) -> Net:
    cam = udp_channel("cam", **(cam_extra or {}))
    d = daemon({"channels": [udp_channel("gcs1"), udp_channel("gcs2"), cam]})
    net = Net(
        d,
        client(udp_url(d.port("gcs1")), *GCS1),
        client(udp_url(d.port("gcs2")), *GCS2),
        client(udp_url(d.port("cam")), *CAM),
        cam_private=bool(cam.get("private")),
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


def _routes(d) -> set[tuple[int, int, str]]:
    """The route table as `gcsd status` shows it (the daemon's control socket)."""
    status = control.query(Path(d.config.state_dir) / control.SOCKET_NAME)
    return {(r["sysid"], r["compid"], r["channel"]) for r in status["routes"]}


# --- plain channels -------------------------------------------------------------------------

def test_command_targeted_at_camera_reaches_only_the_camera_channel(net):
    raw = net.gcs1.send(_command(CAM))
    got = net.after(raw, net.gcs1)
    assert len(got["cam"]) == 1
    assert got["gcs2"] == []
    assert got["gcs1"] == []


def test_vehicle_does_not_answer_a_command_for_another_component_of_its_system(net):
    mark = net.gcs1.mark()
    net.gcs1.send(_command(CAM, M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE))
    # control, through the same socket just after: the vehicle answers a command addressed to it
    net.gcs1.send(_command(VEHICLE, M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_MESSAGE_INTERVAL))
    assert wait_for(net.gcs1, is_ack(M.MAV_CMD_REQUEST_MESSAGE), since=mark, others=net.all)
    intervals = [r.msg.message_id for r in net.gcs1.since(mark, "MESSAGE_INTERVAL") if r.src == VEHICLE]
    assert M.MAVLINK_MSG_ID_ATTITUDE not in intervals
    assert _acks(net.gcs1, mark, M.MAV_CMD_GET_MESSAGE_INTERVAL) == []


def test_broadcast_reaches_every_other_channel_and_is_processed(net):
    mark = net.gcs1.mark()
    raw = net.gcs1.send(_command((0, 0)))
    got = net.after(raw, net.gcs1)
    assert len(got["gcs2"]) == 1
    assert len(got["cam"]) == 1
    assert got["gcs1"] == []
    assert len(_acks(net.gcs1, mark, M.MAV_CMD_GET_MESSAGE_INTERVAL)) == 1


def test_param_request_list_broadcast_reaches_every_other_channel(net):
    raw = net.gcs1.send(M.MAVLink_param_request_list_message(0, 0))
    got = net.after(raw, net.gcs1)
    assert (len(got["gcs2"]), len(got["cam"]), len(got["gcs1"])) == (1, 1, 0)


def test_message_to_our_system_any_component_is_processed_and_copied_to_the_camera(net):
    mark = net.gcs1.mark()
    raw = net.gcs1.send(_command((1, 0)))
    got = net.after(raw, net.gcs1)
    assert len(got["cam"]) == 1
    assert got["gcs2"] == []
    assert got["gcs1"] == []
    acks = _acks(net.gcs1, mark, M.MAV_CMD_GET_MESSAGE_INTERVAL)
    assert [a.msg.result for a in acks] == [M.MAV_RESULT_ACCEPTED]


def test_message_for_the_vehicle_itself_is_processed_and_not_forwarded(net):
    mark = net.gcs1.mark()
    raw = net.gcs1.send(_command(VEHICLE))
    got = net.after(raw, net.gcs1)
    assert got == {"gcs1": [], "gcs2": [], "cam": []}
    assert len(_acks(net.gcs1, mark, M.MAV_CMD_GET_MESSAGE_INTERVAL)) == 1


def test_message_for_an_unknown_system_is_dropped(net):
    mark = net.gcs1.mark()
    raw = net.gcs1.send(_command((77, 1)))
    known = net.gcs1.send(_command(CAM, M.MAV_CMD_IMAGE_STOP_CAPTURE, 0))  # a known node, same window
    got = net.after(raw, net.gcs1)
    assert got == {"gcs1": [], "gcs2": [], "cam": []}
    assert _acks(net.gcs1, mark, M.MAV_CMD_GET_MESSAGE_INTERVAL) == []
    assert [r.raw for r in net.cam.received if r.raw == known] == [known]


def test_heartbeat_is_forwarded_to_every_other_channel_never_back(net):
    raw = net.gcs1.heartbeat()
    got = net.after(raw, net.gcs1)
    assert len(got["gcs2"]) == 1
    assert len(got["cam"]) == 1
    assert got["gcs1"] == []


def test_nothing_from_a_ground_station_ever_comes_back_to_it(net):
    mark = net.gcs1.mark()
    marks2 = net.gcs2.mark()
    sent = [
        net.gcs1.heartbeat(),
        net.gcs1.send(_command((0, 0))),
        net.gcs1.send(_command(CAM)),
        net.gcs1.send(_command((1, 0))),
        net.gcs1.send(M.MAVLink_param_request_list_message(0, 0)),
    ]
    net.barrier(net.gcs1)
    assert [r for r in net.gcs1.since(mark) if r.src == GCS1] == []
    # the control: the heartbeat and the two broadcasts did go out, to the other ground station
    assert sum(1 for r in net.gcs2.since(marks2) if r.raw in sent) == 3


def test_camera_reply_targeted_at_a_ground_station_reaches_only_that_ground_station(net):
    ack = M.MAVLink_command_ack_message(M.MAV_CMD_IMAGE_START_CAPTURE, M.MAV_RESULT_ACCEPTED, 0, 0, *GCS1)
    raw = net.cam.send(ack)
    got = net.after(raw, net.cam)
    assert len(got["gcs1"]) == 1
    assert got["gcs2"] == []
    assert got["cam"] == []


def test_forwarded_frames_are_byte_identical(net):
    raw = net.gcs1.send(_command(CAM, M.MAV_CMD_IMAGE_START_CAPTURE, 0))
    got = net.after(raw, net.gcs1)
    (r,) = got["cam"]
    assert r.raw == raw
    assert (r.msg.get_seq(), r.src, r.msg.command) == (raw[4], GCS1, M.MAV_CMD_IMAGE_START_CAPTURE)


def test_unknown_message_id_is_forwarded_unchanged_as_a_broadcast(net):
    raw = v2_frame(42424, bytes(range(20)), *GCS1, seq=7, crc=b"\xab\xcd")
    net.gcs1.write(raw)
    got = net.after(raw, net.gcs1)
    assert len(got["gcs2"]) == 1
    assert len(got["cam"]) == 1
    assert got["gcs1"] == []
    assert got["gcs2"][0].type == "UNKNOWN_42424"


def test_unknown_message_id_from_a_source_never_seen_with_a_good_frame_is_dropped(net):
    raw = v2_frame(42424, bytes(range(20)), 99, 1)  # its CRC cannot be checked: it could be noise
    net.gcs1.write(raw)
    seen = v2_frame(42424, bytes(range(20)), *GCS1, seq=8)  # control: the same from a known source
    net.gcs1.write(seen)
    got = net.after(raw, net.gcs1)
    assert got == {"gcs1": [], "gcs2": [], "cam": []}
    assert [r.raw for r in net.gcs2.received if r.raw == seen] == [seen]


# --- the route table ------------------------------------------------------------------------

def test_route_table_holds_twenty_routes_and_refuses_the_twenty_first_while_all_are_fresh(net, client):
    """Three routes exist (gcs1, gcs2, cam); 17 more sources on gcs2, each its own (sysid, compid),
    fill the table. The 21st is not learned: a frame targeted at it is dropped, while one targeted
    at the 20th, sent just after on the same socket, is forwarded. Replacement of a route silent
    for 30 s is tested with a float clock in tests/unit/test_router.py."""
    assert _routes(net.d) == {(*GCS1, "gcs1"), (*GCS2, "gcs2"), (*CAM, "cam")}
    swarm = client(udp_url(net.d.port("gcs2")), 100, 1)
    fill = [(100 + i, 1 + i) for i in range(MAX_ROUTES - 3)]  # distinct sysids and compids
    extra = (150, 1)
    for sysid, compid in [*fill, extra]:
        mav = M.MAVLink(swarm.conn, srcSystem=sysid, srcComponent=compid)
        raw = bytes(M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                0, 0, 0, 3).pack(mav))
        swarm.write(raw)
        # each heartbeat is forwarded to gcs1 whether or not its source fits in the table
        assert wait_for(net.gcs1, lambda r, raw=raw: r.raw == raw, others=[*net.all, swarm]), (sysid, compid)

    routes = _routes(net.d)
    assert len(routes) == MAX_ROUTES
    assert {(s, c, "gcs2") for s, c in fill} <= routes
    assert (*extra, "gcs2") not in routes

    mark2 = net.gcs2.mark()
    to_extra = net.gcs1.send(_command(extra, M.MAV_CMD_IMAGE_STOP_CAPTURE, 1))
    to_last = net.gcs1.send(_command(fill[-1], M.MAV_CMD_IMAGE_STOP_CAPTURE, 2))
    assert wait_for(swarm, lambda r: r.raw == to_last, others=net.all), "the 20th route does not work"
    net.barrier(net.gcs1)
    assert [r for r in swarm.received if r.raw == to_extra] == []
    assert [r for r in net.gcs2.since(mark2) if r.raw == to_extra] == []

    # the routes learned before the swarm still work, both ways, and the vehicle still answers
    got = net.after(net.gcs1.send(_command(CAM)), net.gcs1)
    assert (len(got["cam"]), len(got["gcs2"])) == (1, 0)
    ack = M.MAVLink_command_ack_message(M.MAV_CMD_IMAGE_START_CAPTURE, M.MAV_RESULT_ACCEPTED, 0, 0, *GCS1)
    got = net.after(net.cam.send(ack), net.cam)
    assert (len(got["gcs1"]), len(got["gcs2"])) == (1, 0)
    assert _routes(net.d) == routes


# --- a private channel ----------------------------------------------------------------------

def test_private_channel_gets_no_forwarded_broadcasts(private_cam):
    net = private_cam
    raw = net.gcs1.send(_command((0, 0)))
    got = net.after(raw, net.gcs1)
    assert len(got["gcs2"]) == 1
    assert got["cam"] == []
    unknown = v2_frame(42424, bytes(8), *GCS1)
    net.gcs1.write(unknown)
    got = net.after(unknown, net.gcs1)
    assert len(got["gcs2"]) == 1
    assert got["cam"] == []


def test_private_channel_gets_no_forwarded_heartbeats(private_cam):
    net = private_cam
    raw = net.gcs1.heartbeat()
    got = net.after(raw, net.gcs1)
    assert len(got["gcs2"]) == 1
    assert got["cam"] == []
    assert [r for r in net.cam.received if r.type == "HEARTBEAT" and r.src != VEHICLE] == []
    assert [r for r in net.cam.received if r.type == "HEARTBEAT" and r.src == VEHICLE]


def test_private_channel_gets_frames_addressed_exactly_to_a_node_on_it(private_cam):
    net = private_cam
    raw = net.gcs1.send(_command(CAM))
    got = net.after(raw, net.gcs1)
    assert len(got["cam"]) == 1
    assert got["gcs2"] == []


def test_private_channel_still_gets_the_vehicle_telemetry(private_cam):
    net = private_cam
    mark = net.cam.mark()
    assert wait_for(net.cam, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE, since=mark, others=net.all)
    assert wait_for(net.cam, lambda r: r.type == "ATTITUDE" and r.src == VEHICLE, since=mark, others=net.all)


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
    net.barrier(net.cam)  # the ground stations get the vehicle's PARAM_VALUE, so the daemon read them
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
    mark = net.cam.mark()
    sent = [
        net.gcs1.heartbeat(),
        net.gcs1.send(_command((0, 0))),
        net.gcs1.send(_command((1, 0))),
        net.gcs1.send(_command(CAM)),
    ]
    unknown = v2_frame(42424, bytes(8), *GCS1)
    net.gcs1.write(unknown)
    net.barrier(net.gcs1)  # the camera gets the vehicle's PARAM_VALUE: the daemon did write to it
    assert [r for r in net.cam.received if r.src != VEHICLE] == []
    assert [r for r in net.cam.since(mark) if r.src == VEHICLE and r.type == "PARAM_VALUE"]
    assert len([r for r in net.gcs2.received if r.raw in (sent[0], sent[1], unknown)]) == 3


def test_nothing_received_on_a_no_forward_channel_is_forwarded(no_forward_cam):
    net = no_forward_cam
    net.cam.heartbeat(M.MAV_TYPE_CAMERA)
    net.cam.send(M.MAVLink_command_ack_message(M.MAV_CMD_IMAGE_START_CAPTURE, 0, 0, 0, *GCS1))
    net.cam.send(_command((0, 0), M.MAV_CMD_IMAGE_STOP_CAPTURE, 0))
    net.cam.write(v2_frame(42424, bytes(8), *CAM))
    net.barrier(net.cam)  # both ground stations get the vehicle's PARAM_VALUE for the camera's PARAM_SET
    for c in (net.gcs1, net.gcs2):
        assert [r for r in c.received if r.src == CAM] == []


def test_no_forward_channel_peer_is_still_served_by_the_vehicle(no_forward_cam):
    net = no_forward_cam
    mark = net.cam.mark()
    net.cam.send(_command(VEHICLE))
    ack = wait_for(net.cam, is_ack(M.MAV_CMD_GET_MESSAGE_INTERVAL), since=mark, others=net.all)
    assert ack is not None and ack.msg.result == M.MAV_RESULT_ACCEPTED
