"""Issue 17 (items 1, 2) on a real Mosquitto: what a vehicle or a stranger publishes on the broker
cannot pose as another vehicle, and nothing the broker stored earlier is acted on.

1. Every frame of a message on T/up/S/C must come from system S (not only the first, not only
   when the payload starts with STX): a second frame, a frame after garbage, or one hidden inside a
   frame with a bad CRC makes the whole message a counted drop (`spoofed_dropped`).
2. Retained messages (stored by the broker, handed to every new subscriber) are ignored on both
   sides (`retained_dropped`): a force-ARM published once with the retain flag arms nothing.

Each "nothing happened" check has its positive control in the same window: a good multi-frame
message from the right source is routed, a live request published after the retained one is
answered.
"""

from __future__ import annotations

import time

from .helpers import M, packed, pump, udp_url, wait_for
from .test_mqtt import (  # noqa: F401  (broker and tap are fixtures)
    GROUND_SYSID,
    broker,
    ground_side,
    heard_all,
    packed_heartbeat,
    tap,
    vehicle_side,
)

FORCE_ARM = 21196.0


def heartbeat_from(sysid: int, compid: int) -> bytes:
    return packed(M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0, 3),
                  sysid, compid)


def with_bad_crc(frame: bytes, inner: bytes) -> bytes:
    """A frame from `frame`'s source whose payload hides `inner` and whose CRC is wrong: the parser
    drops it and finds `inner` on resync."""
    payload = inner + b"\x00" * (len(frame) - 12 - len(inner)) if len(frame) - 12 > len(inner) else inner
    return bytes([0xFD, len(payload)]) + frame[2:10] + payload + b"\x00\x00"


def test_every_frame_of_an_uplink_message_must_come_from_its_topics_system(broker, daemon, client, tap,  # noqa: F811
                                                                           tmp_path):
    topic = "gcsd/spoof"
    daemon(vehicle_side(tmp_path, "v", broker, topic, sysid=3))
    ground = daemon(ground_side(tmp_path, broker, topic))
    gcs = client(udp_url(ground.port("gcs")))
    assert (3, 1) in heard_all(gcs, {(3, 1)})
    attacker = tap(f"{topic}/nothing")
    up3 = f"{topic}/up/3/1"
    before = ground.stats("fleet")
    mark = gcs.mark()
    attacker.publish(up3, heartbeat_from(3, 1) + heartbeat_from(9, 1))  # the second frame poses as 9
    attacker.publish(up3, b"\x00" + heartbeat_from(11, 1))  # not starting with STX
    attacker.publish(up3, with_bad_crc(heartbeat_from(3, 1), heartbeat_from(12, 1)))  # hidden in a bad frame
    attacker.publish(f"{topic}/up/x/1", heartbeat_from(13, 1))  # a topic with no system at all
    # the positive control, published after them: two frames, both from system 3, are routed
    attacker.publish(up3, heartbeat_from(3, 77) + heartbeat_from(3, 78))
    got = heard_all(gcs, {(3, 77), (3, 78), (3, 1)})
    assert {(3, 77), (3, 78)} <= set(got), "a good multi-frame message is passed on"
    pump([gcs], 0.3)
    sources = {r.src[0] for r in gcs.since(mark, "HEARTBEAT")}
    assert not sources & {9, 11, 12, 13}, f"spoofed systems were routed: {sorted(sources)}"
    routed = {r["sysid"] for r in ground.status()["routes"]}
    assert 3 in routed and not routed & {9, 11, 12, 13}, routed
    after = ground.stats("fleet")
    assert after["spoofed_dropped"] - before["spoofed_dropped"] == 2 + 1 + 1 + 1, after
    status = ground.status()
    fleet = next(c for c in status["channels"] if c["name"] == "fleet")
    assert fleet["spoofed_dropped"] == after["spoofed_dropped"], "shown by gcsd status"


def test_a_retained_force_arm_is_never_executed_and_a_live_request_is(broker, daemon, client, tap,  # noqa: F811
                                                                      tmp_path):
    topic = "gcsd/retained"
    stranger = tap(f"{topic}/nothing")
    arm = packed(M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1.0, FORCE_ARM,
                                                0, 0, 0, 0, 0), GROUND_SYSID, 190)
    stranger.client.publish(f"{topic}/down/1", arm, 0, retain=True).wait_for_publish(5)
    stranger.client.publish(f"{topic}/up/9/1", heartbeat_from(9, 1), 0, retain=True).wait_for_publish(5)
    stored = tap(f"{topic}/#")  # subscribed after the publishing: it gets them only if the broker kept them
    assert wait_for_tap(stored, 0, lambda raw: raw == arm) and wait_for_tap(stored, 0, lambda raw: raw[5] == 9)
    uplink = tap(f"{topic}/up/1/1")
    vehicle = daemon(vehicle_side(tmp_path, "v", broker, topic, sysid=1))
    ground = daemon(ground_side(tmp_path, broker, topic))
    gcs = client(udp_url(ground.port("gcs")))
    assert (1, 1) in heard_all(gcs, {(1, 1)})

    # positive control: a live request published now (after the retained command, on the same
    # subscription, so delivered after it) is answered
    request = packed(M.MAVLink_param_request_read_message(1, 1, b"SYSID_THISMAV", -1), GROUND_SYSID, 190)
    mark = uplink.mark()
    stranger.publish(f"{topic}/down/1", request)
    assert wait_for_tap(uplink, mark, lambda raw: raw[7] == M.MAVLINK_MSG_ID_PARAM_VALUE), "the live request is answered"
    assert not vehicle.status()["vehicles"][0]["armed"], "the retained force-ARM was not executed"
    assert vehicle.stats("fleet")["retained_dropped"] == 1
    mark = gcs.mark()
    pump([gcs], 1.2)
    assert not [r for r in gcs.since(mark, "HEARTBEAT") if r.src == (9, 1)], "a retained uplink is not routed"
    assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == (1, 1), 2.0, mark)
    assert ground.stats("fleet")["retained_dropped"] == 1
    fleet = next(c for c in ground.status()["channels"] if c["name"] == "fleet")
    assert fleet["retained_dropped"] == 1, "shown by gcsd status"


def wait_for_tap(t, mark: int, match, timeout: float = 3.0) -> bool:
    """Whether a payload matching `match` reaches the tap after `mark` within `timeout`."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if any(match(raw) for _, raw in t.since(mark)):
            return True
        time.sleep(0.02)
    return False
