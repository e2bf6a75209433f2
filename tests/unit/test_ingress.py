"""The ingress decision (routing/ingress.py): every frame's fate in one place, with a float `now`.

World: we are (1, 1). Channel 0 has a ground station (255, 190), channel 1 a flight controller
(7, 1); channels 0 and 2 are members of one redundant group where a test says so.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.routing.ingress import DUPLICATE, LOOP, Ingress
from gcsd.routing.router import ChannelPolicy, Router
from gcsd.wire.codec import FrameParser, ParseStats
from gcsd.wire.signing import Signing

KEY = bytes(range(32))


@dataclass
class Ch:
    index: int
    dedup: bool = False
    sign_forwarded: bool = False
    unsigned_ok: bool = False
    stream_requests: object | None = None


def frame(msg, sysid=255, compid=190):
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    return FrameParser(ParseStats()).feed(bytes(msg.pack(mav)))[0]


def heartbeat(sysid=255, compid=190, mav_type=M.MAV_TYPE_GCS):
    return frame(M.MAVLink_heartbeat_message(mav_type, 8, 0, 0, 0, 3), sysid, compid)


def command(target_system, target_component=1, sysid=255):
    return frame(M.MAVLink_command_long_message(target_system, target_component, 400, 0, 1, 0, 0, 0, 0, 0, 0),
                 sysid)


def ingress(signing=None, dedup_ms=0, groups=(None, None, None)) -> Ingress:
    router = Router({(1, 1)}, [ChannelPolicy(group=g) for g in groups])
    ing = Ingress(router, signing or Signing(), dedup_ms)
    ing.decide(Ch(0), heartbeat(), 0.0)
    ing.decide(Ch(1), heartbeat(7, 1, M.MAV_TYPE_QUADROTOR), 0.0)
    return ing


def test_a_command_to_us_is_handled_here_and_forwarded_nowhere():
    fate = ingress().decide(Ch(0), command(1), 1.0)
    assert (fate.drop, fate.forward, fate.local, fate.tap) == (None, (), True, True)


def test_a_command_to_the_flight_controller_goes_to_its_channel_only():
    fate = ingress().decide(Ch(0), command(7), 1.0)
    assert (fate.forward, fate.local) == ((1,), False)


def test_a_forwarded_frame_coming_back_is_a_loop():
    ing = ingress()
    cmd = command(7)
    assert ing.decide(Ch(0), cmd, 1.0).forward == (1,)
    assert ing.decide(Ch(1), cmd, 1.2) is LOOP
    assert ing.decide(Ch(1), cmd, 1.6).drop is None  # LOOP_WINDOW_S later: forgotten


def test_a_copy_from_another_member_of_a_group_is_a_duplicate_and_the_first_passes():
    ing = ingress(groups=("lte", None, "lte"))
    cmd = command(7)
    assert ing.decide(Ch(0, dedup=True), cmd, 1.0).drop is None
    assert ing.decide(Ch(2, dedup=True), cmd, 1.1) is DUPLICATE


def test_with_dedup_ms_every_channel_is_checked_within_the_window_only():
    ing = ingress(dedup_ms=200)
    cmd = command(1)
    assert ing.decide(Ch(0), cmd, 1.0).drop is None
    assert ing.decide(Ch(2), cmd, 1.1) is DUPLICATE
    assert ing.decide(Ch(2), cmd, 1.5).drop is None  # the window has passed


def test_a_sign_forwarded_channel_gets_its_frames_signed_and_the_signed_bytes_make_the_loop():
    ing = ingress(Signing(KEY))
    cmd = command(7)
    fate = ing.decide(Ch(0, sign_forwarded=True), cmd, 1.0)
    assert fate.sign and fate.forward == (1,)
    out = ing.signed(Ch(0), cmd.raw, 1.0, 1.8e9)
    assert out != cmd.raw and out[2] & 0x01  # MAVLINK_IFLAG_SIGNED
    parsed = FrameParser(ParseStats()).feed(out)[0]
    assert ing.decide(Ch(1), parsed, 1.2) is LOOP


def test_without_a_key_the_gateway_signs_nothing():
    fate = ingress().decide(Ch(0, sign_forwarded=True), command(7), 1.0)
    assert not fate.sign and fate.forward == (1,)


def test_stream_requests_are_asked_for_on_a_heartbeat_only_where_the_channel_makes_them():
    ing = ingress()
    assert ing.decide(Ch(1, stream_requests=object()), heartbeat(7, 1, M.MAV_TYPE_QUADROTOR), 2.0).streams
    assert not ing.decide(Ch(1, stream_requests=object()), command(1, sysid=7), 2.0).streams
    assert not ing.decide(Ch(1), heartbeat(7, 1, M.MAV_TYPE_QUADROTOR), 3.0).streams


def test_a_radio_status_does_not_make_a_channel_active_and_a_heartbeat_does():
    ing = ingress()
    radio = frame(M.MAVLink_radio_status_message(200, 200, 40, 0, 0, 0, 0), 51, 68)
    ing.decide(Ch(2), radio, 1.0)
    assert 2 not in ing.active
    ing.decide(Ch(2), heartbeat(9, 1), 1.0)
    assert 2 in ing.active


def test_the_same_fate_is_one_object():
    ing = ingress()
    assert ing.decide(Ch(0), command(1), 1.0) is ing.decide(Ch(0), command(1), 2.0)


def test_a_bad_crc_frame_goes_to_every_broadcast_channel_once_then_is_a_loop():
    ing = ingress()
    raw = bytes(command(0).raw[:-2]) + b"\x00\x00"
    assert ing.bad_crc(Ch(0), raw, 1.0) == (1,)
    assert ing.bad_crc(Ch(1), raw, 1.1) is None
    assert ing.bad_crc_forwarded == 1


def test_verify_refuses_an_unsigned_frame_where_signing_is_required_and_accepts_it_where_unsigned_ok():
    ing = ingress(Signing(KEY, require=True))
    assert ing.verify(Ch(0), command(1), 1.8e9) is not None
    assert ing.verify(Ch(0, unsigned_ok=True), command(1), 1.8e9) is None
