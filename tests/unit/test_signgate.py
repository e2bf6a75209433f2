"""The signing gateway: an unsigned frame re-framed and signed, checked by pymavlink and by our own
signing core (bytes compared: this is a codec test)."""

import pytest
from pymavlink.dialects.v10 import ardupilotmega as V1
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.routing.signgate import signed_copy
from gcsd.wire.signing import Signing, wall_to_units

KEY = bytes(range(32))
WALL_S = 1_800_000_000.0


def _cmd():
    return M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)


def _packed(msg, version: int) -> bytes:
    mav = (M if version == 2 else V1).MAVLink(None, srcSystem=255, srcComponent=190)
    mav.seq = 42
    return bytes(msg.pack(mav))


@pytest.mark.parametrize("version", [1, 2])
def test_an_unsigned_frame_is_signed_and_accepted_by_pymavlink_and_by_a_signing_receiver(version):
    msg = _cmd() if version == 2 else V1.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    timestamp = wall_to_units(WALL_S)
    signed = signed_copy(_packed(msg, version), KEY, 3, timestamp)
    receiver = M.MAVLink(None)
    receiver.signing.secret_key = KEY
    receiver.signing.sig_check = True  # pymavlink's check of the signature
    decoded = receiver.decode(bytearray(signed))
    assert decoded.get_type() == "COMMAND_LONG" and decoded.command == 400 and decoded.param1 == 1
    assert (decoded.get_srcSystem(), decoded.get_srcComponent(), decoded.get_seq()) == (255, 190, 42)
    assert signed[-13] == 3 and int.from_bytes(signed[-12:-6], "little") == timestamp
    core = Signing(KEY, timestamp - 1, require=True)
    assert core.check(signed, 76, 255, 190, False, WALL_S) is None
    assert core.check(signed, 76, 255, 190, False, WALL_S) == "replay"


def test_a_frame_signed_with_another_key_is_refused():
    signed = signed_copy(_packed(_cmd(), 2), bytes(32), 0, wall_to_units(WALL_S))
    assert Signing(KEY, 0, require=True).check(signed, 76, 255, 190, False, WALL_S) == "bad_signature"


def test_signed_or_unknown_frames_are_not_touched():
    signed = signed_copy(_packed(_cmd(), 2), KEY, 0, 1)
    assert signed_copy(signed, KEY, 0, 2) is None
    unknown = bytes([0xFD, 1, 0, 0, 0, 255, 190, 0x99, 0x99, 0x00, 7, 0x12, 0x34])
    assert signed_copy(unknown, KEY, 0, 2) is None
