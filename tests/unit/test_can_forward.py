"""CAN over MAVLink's core (gcsd.payloads.can.forward) with a fake clock: AP_MAVLinkCAN's answers, the 5 s
timeout, filters, several clients, the bounded inbound buffer."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.payloads.can.forward import (
    EXTENDED_FLAG,
    FORWARD_TIMEOUT_S,
    INBOUND_BUFFER,
    MAX_CLIENTS,
    CanForwarder,
    CanFrame,
    Client,
    dronecan_id,
    frame_message,
)

ACCEPTED, FAILED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_FAILED
GUI = Client(0, 250, 189)
OTHER = Client(1, 255, 190)


def node_status_id(source: int) -> int:
    return EXTENDED_FLAG | (16 << 24) | (341 << 8) | source  # priority 16, NodeStatus (341)


def get_node_info_request(source: int, dest: int) -> int:
    return EXTENDED_FLAG | (30 << 24) | (1 << 16) | (1 << 15) | (dest << 8) | 0x80 | source


def test_forward_starts_on_an_existing_bus_and_fails_on_a_missing_one():
    f = CanForwarder(2)
    assert f.request(GUI, 3, 0.0) == FAILED and not f.clients
    assert f.request(GUI, 2, 0.0) == ACCEPTED
    assert f.from_bus(CanFrame(1, node_status_id(10), b"\1" * 7), 1.0) == [GUI]
    assert f.from_bus(CanFrame(0, node_status_id(10), b"\1" * 7), 1.0) == []
    assert f.request(GUI, 0, 2.0) == ACCEPTED  # stop
    assert f.from_bus(CanFrame(1, node_status_id(10), b""), 2.0) == []
    assert f.request(OTHER, 0, 2.0) == ACCEPTED  # nothing to stop: still accepted


def test_forwarding_stops_five_seconds_after_the_last_request():
    f = CanForwarder(1)
    f.request(GUI, 1, 0.0)
    assert f.next_deadline() == FORWARD_TIMEOUT_S
    f.request(GUI, 1, 3.0)  # refreshed
    assert f.from_bus(CanFrame(0, node_status_id(1), b""), 7.9) == [GUI]
    assert f.expire(8.0) == []
    assert f.expire(8.01) == [GUI]
    assert f.from_bus(CanFrame(0, node_status_id(1), b""), 8.1) == []
    assert f.next_deadline() is None


def test_several_clients_each_get_the_bus_with_their_own_filter():
    f = CanForwarder(1)
    f.request(GUI, 1, 0.0)
    f.request(OTHER, 1, 0.0)
    assert f.filter_modify(OTHER, 1, M.CAN_FILTER_REPLACE, [341])
    status, info = CanFrame(0, node_status_id(5), b""), CanFrame(0, get_node_info_request(127, 5), b"")
    assert f.from_bus(status, 1.0) == [GUI, OTHER]
    assert f.from_bus(info, 1.0) == [GUI]
    assert f.filter_modify(OTHER, 1, M.CAN_FILTER_ADD, [1, 341])
    assert f.from_bus(info, 1.0) == [GUI, OTHER]
    assert f.filter_modify(OTHER, 1, M.CAN_FILTER_REMOVE, [341])
    assert f.from_bus(status, 1.0) == [GUI]
    assert not f.filter_modify(OTHER, 2, M.CAN_FILTER_REPLACE, [1])  # not its bus (1-based)
    assert f.filter_modify(OTHER, 1, M.CAN_FILTER_REPLACE, [])  # no filter again
    assert f.from_bus(status, 1.0) == [GUI, OTHER]


def test_dronecan_ids_of_message_service_and_anonymous_frames():
    assert dronecan_id(node_status_id(9)) == 341
    assert dronecan_id(get_node_info_request(127, 9)) == 1
    assert dronecan_id(EXTENDED_FLAG | (341 << 8)) == 0


def test_client_limit_drops_the_longest_silent():
    f = CanForwarder(1)
    clients = [Client(0, 200 + n, 1) for n in range(MAX_CLIENTS + 1)]
    for n, c in enumerate(clients):
        f.request(c, 1, float(n) * 0.1)
    assert clients[0] not in f.clients and len(f.clients) == MAX_CLIENTS


def test_inbound_frames_are_bounded_and_checked():
    f = CanForwarder(1)
    assert not f.from_client(1, 8, 1, b"\0" * 8, False)  # no such bus
    assert not f.from_client(0, 9, 1, b"\0" * 9, False)  # longer than a classic frame
    assert f.from_client(0, 12, 1, b"\1" * 64, True)  # CAN FD may carry 12
    for n in range(INBOUND_BUFFER):
        f.from_client(0, 1, n, bytes([n]), False)
    assert f.dropped_inbound == 1 and f.refused_inbound == 2
    frames = f.take()
    assert len(frames) == INBOUND_BUFFER and frames[0].data == b"\1" * 12 and frames[0].fd
    assert f.take() == []


def test_frame_messages_carry_bus_len_id_and_padded_data():
    msg = frame_message(CanFrame(0, node_status_id(3), b"\1\2\3"), GUI)
    assert msg.get_type() == "CAN_FRAME"
    assert (msg.target_system, msg.target_component, msg.bus, msg.len, msg.id) == (250, 189, 0, 3, node_status_id(3))
    assert bytes(msg.data) == b"\1\2\3" + b"\0" * 5
    fd = frame_message(CanFrame(1, 5, b"\7" * 20, fd=True), GUI)
    assert fd.get_type() == "CANFD_FRAME" and fd.len == 20 and len(fd.data) == 64
