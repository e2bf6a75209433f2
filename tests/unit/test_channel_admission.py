"""Channel details beside tests/unit/test_channel.py: what a rejected frame leaves in the counters,
sequence numbers per output version, truncated datagrams from strangers, and the unheard
connection dropped first when max_peers are served. Float clock, in-memory writers."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v10 import ardupilotmega as M1
from pymavlink.dialects.v20 import ardupilotmega as M
from receivers import Recorder

from gcsd.config import parse_config
from gcsd.links.channel import Channel


def make_channel(verdict: str | None = None, **extra) -> tuple[Channel, dict, list]:
    conf = {"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0", **extra}
    config = parse_config(f"channels: [{conf!r}]".replace("'", '"'), "t.yaml").channels[0]
    clock = [0.0]
    receiver = Recorder(verdict)
    ch = Channel(0, config, lambda: clock[0], receiver=receiver)
    outbox: dict[object, list[bytes]] = {}
    ch.make_writer = lambda key: (lambda data: outbox.setdefault(key, []).append(data) or True)
    return ch, outbox, receiver


def heartbeat(sysid=255, v1=False) -> bytes:
    mav = (M1 if v1 else M).MAVLink(None, srcSystem=sysid, srcComponent=190)
    return bytes(mav.heartbeat_encode(6, 8, 0, 0, 0).pack(mav, force_mavlink1=v1))


def datagram(ch: Channel, addr, data: bytes, now: float = 0.0) -> None:
    peer = ch.peers.get(addr) or ch.stranger(addr, now)
    ch.receive(peer, data, now, datagram=True)


def test_a_rejected_frame_admits_nobody_and_changes_no_counter_but_the_rejects():
    ch, _outbox, receiver = make_channel("unsigned")
    datagram(ch, ("10.0.0.1", 5), heartbeat())
    assert ch.peers == {} and receiver.frames == [] and receiver.rejects == ["unsigned"]
    snap = ch.snapshot()
    assert snap["packets_in"] == 0 and snap["bytes_in"] == 0


def test_each_version_has_its_own_sequence_numbers():
    ch, outbox, _handled = make_channel()
    old, new = ("10.0.0.1", 1), ("10.0.0.2", 2)
    datagram(ch, old, heartbeat(v1=True))
    datagram(ch, new, heartbeat())
    for _ in range(3):
        ch.send_message(M.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3), 1, 1)
    assert [f[2] for f in outbox[old]] == [0, 1, 2]  # MAVLink1 seq at offset 2
    assert [f[4] for f in outbox[new]] == [0, 1, 2]  # MAVLink2 seq at offset 4


@pytest.mark.parametrize("garbage", [b"\xfd" + bytes(300), b"\xfe\x05" + bytes(3)])
def test_a_truncated_datagram_leaves_nothing_behind_for_the_next(garbage):
    ch, _outbox, handled = make_channel()
    datagram(ch, ("a", 1), garbage)
    datagram(ch, ("b", 2), heartbeat())
    assert [(f.sysid, f.name) for f in handled.frames] == [(255, "HEARTBEAT")] and list(ch.peers) == [("b", 2)]


def test_a_connection_that_never_sent_a_good_frame_is_dropped_before_a_talking_station():
    ch, _outbox, _handled = make_channel(type="tcp-server", max_peers=2)
    closed = []
    ch.connect_peer("station", lambda data: True, lambda: closed.append("station"))
    ch.receive(ch.peers["station"], heartbeat(), 1.0)
    ch.clock = lambda: 5.0
    ch.connect_peer("idle-1", lambda data: True, lambda: closed.append("idle-1"))
    ch.connect_peer("idle-2", lambda data: True, lambda: closed.append("idle-2"))
    assert set(ch.peers) == {"station", "idle-2"} and closed == ["idle-1"]
