"""Channel admission, per-peer versions and the per-channel sweep, with a float clock and
in-memory writers (no sockets, no event loop)."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v10 import ardupilotmega as M1
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.channel import UDP_PEER_TIMEOUT_S, Channel
from gcsd.config import parse_config


def make_channel(**extra) -> tuple[Channel, dict, list]:
    conf = {"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0", **extra}
    config = parse_config(f"channels: [{conf!r}]".replace("'", '"'), "t.yaml").channels[0]
    clock = [0.0]
    ch = Channel(0, config, lambda: clock[0])
    outbox: dict[object, list[bytes]] = {}
    ch.make_writer = lambda key: (lambda data: outbox.setdefault(key, []).append(data) or True)
    handled: list = []
    ch.on_frame = lambda channel, frame, now: handled.append((frame.sysid, frame.name))
    return ch, outbox, handled


def heartbeat(sysid=255, v1=False) -> bytes:
    mav = (M1 if v1 else M).MAVLink(None, srcSystem=sysid, srcComponent=190)
    return bytes(mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav, force_mavlink1=v1))


def radio_status() -> bytes:
    mav = M.MAVLink(None, srcSystem=51, srcComponent=68)
    return bytes(mav.radio_status_encode(200, 200, 100, 0, 0, 0, 0).pack(mav))


def datagram(ch: Channel, addr, data: bytes, now: float = 0.0) -> None:
    peer = ch.peers.get(addr) or ch.stranger(addr, now)
    ch.receive(peer, data, now, datagram=True)


def test_garbage_from_an_unknown_address_creates_no_peer_and_is_counted():
    ch, outbox, handled = make_channel()
    for i in range(100):
        datagram(ch, ("10.0.0.1", 1000 + i), b"\x00\xfd\x09")
    assert ch.peers == {} and outbox == {} and handled == []
    assert ch.snapshot()["parse_errors"] >= 100


def test_a_good_frame_admits_its_sender_and_only_then_it_is_written_to():
    ch, outbox, handled = make_channel()
    datagram(ch, ("10.0.0.1", 5), heartbeat())
    assert list(ch.peers) == [("10.0.0.1", 5)] and handled == [(255, "HEARTBEAT")]
    ch.write(b"frame")
    assert outbox == {("10.0.0.1", 5): [b"frame"]}


def test_a_rejected_frame_admits_nobody_and_changes_no_counter_but_the_rejects():
    ch, outbox, handled = make_channel()
    ch.verify = lambda frame: "unsigned"
    rejects = []
    ch.on_reject = lambda channel, frame, reason, now: rejects.append(reason)
    datagram(ch, ("10.0.0.1", 5), heartbeat())
    assert ch.peers == {} and handled == [] and rejects == ["unsigned"]
    snap = ch.snapshot()
    assert snap["packets_in"] == 0 and snap["bytes_in"] == 0


def test_radio_status_alone_admits_nobody():
    ch, outbox, handled = make_channel()
    datagram(ch, ("10.0.0.1", 5), radio_status())
    assert ch.peers == {} and handled == [(51, "RADIO_STATUS")]


def test_each_peer_keeps_its_own_version_and_it_only_goes_up():
    ch, outbox, handled = make_channel()
    old, new = ("10.0.0.1", 1), ("10.0.0.2", 2)
    datagram(ch, old, heartbeat(v1=True))
    datagram(ch, new, heartbeat())
    ch.send_message(M.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3), 1, 1)
    assert outbox[old][-1][0] == 0xFE and outbox[new][-1][0] == 0xFD
    datagram(ch, new, heartbeat(v1=True))  # a MAVLink1 frame never takes a MAVLink2 peer back
    datagram(ch, old, heartbeat())  # a MAVLink2 frame upgrades
    ch.send_message(M.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3), 1, 1)
    assert outbox[old][-1][0] == 0xFD and outbox[new][-1][0] == 0xFD


def test_each_version_has_its_own_sequence_numbers():
    ch, outbox, handled = make_channel()
    old, new = ("10.0.0.1", 1), ("10.0.0.2", 2)
    datagram(ch, old, heartbeat(v1=True))
    datagram(ch, new, heartbeat())
    for _ in range(3):
        ch.send_message(M.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3), 1, 1)
    assert [f[2] for f in outbox[old]] == [0, 1, 2]  # MAVLink1 seq at offset 2
    assert [f[4] for f in outbox[new]] == [0, 1, 2]  # MAVLink2 seq at offset 4


def test_more_than_max_peers_replaces_the_one_silent_the_longest():
    ch, outbox, handled = make_channel(max_peers=2)
    datagram(ch, ("a", 1), heartbeat(), now=1.0)
    datagram(ch, ("b", 2), heartbeat(), now=2.0)
    datagram(ch, ("a", 1), heartbeat(), now=3.0)
    datagram(ch, ("c", 3), heartbeat(), now=4.0)
    assert set(ch.peers) == {("a", 1), ("c", 3)}
    assert ch.snapshot()["peers_replaced"] == 1


def test_sweep_forgets_a_peer_silent_for_30_s_on_this_channel_only():
    ch, outbox, handled = make_channel()
    other, _, _ = make_channel()
    datagram(ch, ("a", 1), heartbeat(), now=0.0)
    datagram(other, ("b", 2), heartbeat(), now=0.0)
    for t in range(1, 31):
        other.sweep(float(t))  # a busy channel sweeping often takes nothing from the other's
    assert ch.sweep(UDP_PEER_TIMEOUT_S - 0.5) == []
    assert ch.sweep(UDP_PEER_TIMEOUT_S + 0.6) == [("a", 1)]
    assert ch.peers == {} and ch.snapshot()["peers_forgotten"] == 1


@pytest.mark.parametrize("garbage", [b"\xfd" + bytes(300), b"\xfe\x05" + bytes(3)])
def test_a_truncated_datagram_leaves_nothing_behind_for_the_next(garbage):
    ch, outbox, handled = make_channel()
    datagram(ch, ("a", 1), garbage)
    datagram(ch, ("b", 2), heartbeat())
    assert handled == [(255, "HEARTBEAT")] and list(ch.peers) == [("b", 2)]
