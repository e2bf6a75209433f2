"""Companion-computer bridge end to end: ground stations on UDP reach a flight controller on a
serial line through gcsd's router, and gcsd's own component (companion, compid 191) on the same
links. See bridge.py for the setup."""

from __future__ import annotations

import pytest

from .bridge import NullModem, bridge_configs
from .helpers import Client, M, is_type, pump, pump_until, udp_url, wait_for

FC = (1, 1)
COMPANION = (1, 191)


@pytest.fixture
def bridge(daemon, tmp_path):
    modem = NullModem()
    fc_conf, companion_conf = bridge_configs(tmp_path, modem)
    fc = daemon(fc_conf)
    companion = daemon(companion_conf)
    yield companion
    companion.stop()
    fc.stop()
    modem.close()


def heartbeat_sources(c: Client) -> dict[tuple[int, int], int]:
    return {r.src: r.msg.type for r in c.received if r.type == "HEARTBEAT"}


def served_by_the_flight_controller(c: Client) -> None:
    """c's heartbeat read by the companion (its UDP servers answer only peers they have read) and
    the flight controller's route known to it (its frames reach c), awaited, not assumed."""
    c.heartbeat()
    assert wait_for(c, lambda r: r.src == FC, timeout=10.0), "nothing from the flight controller"


def test_ground_stations_see_the_flight_controller_and_the_companion(bridge, client):
    g1 = client(udp_url(bridge.port("gcs1")), 255, 190)
    g2 = client(udp_url(bridge.port("gcs2")), 254, 190)
    served_by_the_flight_controller(g1)  # gcs1 has a peer before g2's heartbeat is routed to it
    g2.heartbeat()  # ground stations heartbeat at 1 Hz; this one reaches gcs1, now active
    wanted = {FC, COMPANION, (254, 190)}
    pump_until([g1, g2], lambda: wanted <= set(heartbeat_sources(g1)))
    seen = heartbeat_sources(g1)
    assert seen[FC] == M.MAV_TYPE_QUADROTOR
    assert seen[COMPANION] == M.MAV_TYPE_ONBOARD_CONTROLLER
    assert (254, 190) in seen, "the other ground station's heartbeat is forwarded"


def test_flight_controller_parameters_through_the_router(bridge, client):
    g1 = client(udp_url(bridge.port("gcs1")), 255, 190)
    served_by_the_flight_controller(g1)
    mark = g1.mark()
    g1.send(M.MAVLink_param_request_list_message(*FC))

    def complete() -> bool:
        values = g1.since(mark, "PARAM_VALUE")
        return bool(values) and len({r.msg.param_index for r in values}) >= values[0].msg.param_count

    # the whole list is awaited, however long a loaded machine takes, then 1 s more for any
    # answer from another component
    pump_until([g1], complete, timeout_s=20.0)
    pump([g1], 1.0)
    values = [r for r in g1.since(mark, "PARAM_VALUE")]
    assert values and {r.src for r in values} == {FC}, "only the flight controller answers its list"
    assert len({r.msg.param_index for r in values}) == values[0].msg.param_count
    # a set reaches the flight controller and is confirmed from it
    mark = g1.mark()
    g1.send(M.MAVLink_param_set_message(*FC, b"RC7_TRIM", 1555.0, M.MAV_PARAM_TYPE_INT16))
    r = wait_for(g1, lambda r: r.type == "PARAM_VALUE" and r.src == FC and r.msg.param_id == "RC7_TRIM", since=mark)
    assert r is not None and r.msg.param_value == 1555.0


def test_companion_component_answers_for_itself_on_the_same_link(bridge, client):
    g2 = client(udp_url(bridge.port("gcs2")), 254, 190)
    g2.heartbeat()
    assert wait_for(g2, lambda r: r.src == COMPANION), "the companion does not serve gcs2"
    mark = g2.mark()
    g2.send(M.MAVLink_param_request_read_message(*COMPANION, b"SYSID_THISMAV", -1))
    r = wait_for(g2, is_type("PARAM_VALUE"), since=mark, timeout=3)
    assert r is not None and r.src == COMPANION and r.msg.param_value == 1.0
    mark = g2.mark()
    g2.command_long(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, target=COMPANION)
    r = wait_for(g2, lambda r: r.type == "AUTOPILOT_VERSION", since=mark, timeout=3)
    assert r is not None and r.src == COMPANION


def test_flight_controller_mission_through_the_router(bridge, client):
    g1 = client(udp_url(bridge.port("gcs1")), 255, 190)
    served_by_the_flight_controller(g1)
    items = [
        M.MAVLink_mission_item_int_message(*FC, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_CMD_NAV_WAYPOINT,
                                           0, 1, 0, 0, 0, 0, int(-35.36e7) + seq * 1000, int(149.16e7), 30.0)
        for seq in range(6)
    ]
    mark = g1.mark()
    g1.send(M.MAVLink_mission_count_message(*FC, len(items), 0))
    ack = None
    seen = mark
    for _ in range(200):
        pump([g1], 0.05)
        for r in g1.received[seen:]:
            if r.src == FC and r.type in ("MISSION_REQUEST", "MISSION_REQUEST_INT"):
                g1.send(items[r.msg.seq])
            elif r.src == FC and r.type == "MISSION_ACK":
                ack = r.msg.type
        seen = len(g1.received)
        if ack is not None:
            break
    assert ack == M.MAV_MISSION_ACCEPTED
    mark = g1.mark()
    g1.send(M.MAVLink_mission_request_list_message(*FC, 0))
    count = wait_for(g1, lambda r: r.type == "MISSION_COUNT" and r.src == FC, since=mark)
    assert count is not None and count.msg.count == 6
