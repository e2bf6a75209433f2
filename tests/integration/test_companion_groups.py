"""Redundant links (SPEC.md "Companion routing", `group`): a fake flight controller (sysid 7) on two
links of one group, radio and LTE, sends every frame on both, byte-identical, as a flight
controller with two telemetry ports does. A ground station on a third channel gets each frame
once; a command for the flight controller goes out on both links; when one link dies the other
carries everything, with no reconnect of the ground station."""

from __future__ import annotations

from .helpers import M, from_vehicle, udp_channel, udp_url, wait_for

FC = (7, 1)


def _attitude(i: int):
    return M.MAVLink_attitude_message(i, 0.1, 0.2, 0.3, 0, 0, 0)


def _command():
    return M.MAVLink_command_long_message(*FC, M.MAV_CMD_REQUEST_MESSAGE, 0, 148, 0, 0, 0, 0, 0, 0)


def test_two_links_of_a_group_deliver_once_and_the_survivor_carries_everything(daemon, client):
    d = daemon({"channels": [udp_channel("radio", group="fc"), udp_channel("lte", group="fc"), udp_channel("gcs")]})
    radio = client(udp_url(d.port("radio")), *FC)
    lte = client(udp_url(d.port("lte")), *FC)
    gcs = client(udp_url(d.port("gcs")), 255, 190)
    everyone = [radio, lte, gcs]
    heartbeat = radio.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                       0, 0, 0, 3))
    lte.write(heartbeat)  # the same bytes on the second link
    gcs.heartbeat()
    for c in everyone:
        assert wait_for(c, from_vehicle, others=everyone)

    mark = gcs.mark()
    sent = []
    for i in range(20):
        raw = radio.send(_attitude(i))
        lte.write(raw)
        sent.append(raw)
    # barriers: one frame of its own behind the copies on each link's socket; once both are
    # through, every copy has been read, whichever socket the daemon drained first
    barriers = [radio.send(_attitude(98)), lte.send(_attitude(99))]
    for barrier in barriers:
        assert wait_for(gcs, lambda r, b=barrier: r.raw == b, since=mark, others=everyone)
    got = [r.raw for r in gcs.since(mark) if r.src == FC]
    assert got[:20] == sent and sorted(got[20:]) == sorted(barriers)  # each exactly once, in order
    duplicates = {c["name"]: c["duplicates"] for c in d.status()["channels"]}
    # the heartbeat's and the 20 attitudes' second copies, counted on the link that read each
    # second (the daemon may drain either socket first)
    assert duplicates["radio"] + duplicates["lte"] == 21 and duplicates["gcs"] == 0, duplicates

    marks = {c: c.mark() for c in everyone}
    command = gcs.send(_command())
    for link in (radio, lte):  # a frame for the flight controller goes out on every link of the group
        assert wait_for(link, lambda r: r.raw == command, since=marks[link], others=everyone)

    radio.close()  # the radio link dies
    everyone = [lte, gcs]
    mark = gcs.mark()
    carried = [lte.send(_attitude(100 + i)) for i in range(10)]
    assert wait_for(gcs, lambda r: r.raw == carried[-1], since=mark, others=everyone)
    assert [r.raw for r in gcs.since(mark) if r.src == FC] == carried
    lte_mark = lte.mark()
    command = gcs.send(_command())
    assert wait_for(lte, lambda r: r.raw == command, since=lte_mark, others=everyone)


def test_dedup_ms_drops_the_same_frame_from_any_channel(daemon, client):
    d = daemon({"routing": {"dedup_ms": 500},
                "channels": [udp_channel("a"), udp_channel("b"), udp_channel("gcs")]})
    a = client(udp_url(d.port("a")), *FC)
    b = client(udp_url(d.port("b")), 8, 1)
    gcs = client(udp_url(d.port("gcs")), 255, 190)
    everyone = [a, b, gcs]
    for c in everyone:
        c.heartbeat(M.MAV_TYPE_QUADROTOR if c is not gcs else M.MAV_TYPE_GCS)
    for c in everyone:
        assert wait_for(c, from_vehicle, others=everyone)
    mark = gcs.mark()
    raw = a.send(_attitude(1))
    b.write(raw)  # the same bytes on another channel, not a group: dropped by dedup_ms
    control = b.send(_attitude(2))
    assert wait_for(gcs, lambda r: r.raw == control, since=mark, others=everyone)
    assert [r.raw for r in gcs.since(mark) if r.raw == raw] == [raw]
    assert {c["name"]: c["duplicates"] for c in d.status()["channels"]}["b"] == 1

