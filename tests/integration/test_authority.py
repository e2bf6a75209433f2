"""Authority (SPEC.md "Authority", issue 30) against the real daemon: pymavlink stations signed
with different keys, each role's refusal answered by the protocol, a positive control in each."""

from __future__ import annotations

import hashlib

from .helpers import VEHICLE, Client, M, is_ack, udp_channel, udp_url, wait_for
from .test_signing import KEY, now_units, sign

OPERATOR_KEY = hashlib.sha256(b"operator passphrase").digest()
OBSERVER_PASSPHRASE = "lte viewer passphrase"
OBSERVER_KEY = hashlib.sha256(OBSERVER_PASSPHRASE.encode()).digest()
ADMIN_KEY = hashlib.sha256(b"admin").digest()
FORCE = 21196


def roles_daemon(daemon, tmp_path, **extra):
    keys = tmp_path / "keys"
    keys.mkdir()
    (keys / "op.key").write_text(OPERATOR_KEY.hex() + "\n")
    (keys / "viewer.txt").write_text(OBSERVER_PASSPHRASE + "\n")
    (keys / "admin.key").write_text(ADMIN_KEY.hex() + "\n")
    return daemon({
        "state_dir": str(tmp_path / "st"),
        "signing": {"key": KEY.hex(), "require": True, "keys": [
            {"name": "alice", "key_file": str(keys / "op.key"), "role": "operator"},
            {"name": "viewer", "passphrase_file": str(keys / "viewer.txt"), "role": "observer"},
            {"name": "root", "key_file": str(keys / "admin.key"), "role": "admin"},
        ]},
        "channels": [udp_channel("gcs")],
        **extra,
    })


def station(client, d, key: bytes, sysid: int, link_id: int) -> Client:
    """A station signing with its own key. The daemon signs what it sends with the vehicle's key
    (signing.key; replies signed with each station's key are not built yet), which pymavlink
    cannot check with another key: the station accepts what it cannot verify."""
    c = client(udp_url(d.port("gcs")), sysid, 190)
    sign(c, key, link_id=link_id)
    c.mav.signing.allow_unsigned_callback = lambda mav, msgid: True
    c.heartbeat()
    return c


def armed(c: Client, timeout: float = 3.0):
    return wait_for(c, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE
                    and r.msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, timeout, since=c.mark())


def command_result(c: Client, command: int, *params: float) -> int | None:
    mark = c.mark()
    c.command_long(command, *params)
    ack = wait_for(c, is_ack(command), since=mark)
    return None if ack is None else ack.msg.result


def test_observer_arm_denied_operator_arms(daemon, client, tmp_path):
    d = roles_daemon(daemon, tmp_path)
    viewer = station(client, d, OBSERVER_KEY, 240, 3)
    alice = station(client, d, OPERATOR_KEY, 241, 4)
    assert wait_for(viewer, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE), "the observer hears telemetry"
    assert command_result(viewer, M.MAV_CMD_COMPONENT_ARM_DISARM, 1, FORCE) == M.MAV_RESULT_DENIED
    assert d.stats("gcs")["denied"] >= 1
    heartbeat = wait_for(alice, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE, since=alice.mark())
    assert not heartbeat.msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, "the observer's ARM changed nothing"
    assert command_result(alice, M.MAV_CMD_COMPONENT_ARM_DISARM, 1, FORCE) == M.MAV_RESULT_ACCEPTED
    assert armed(alice), "the operator armed it (the positive control)"


def test_observer_param_set_gets_the_unchanged_value(daemon, client, tmp_path):
    d = roles_daemon(daemon, tmp_path)
    viewer = station(client, d, OBSERVER_KEY, 240, 3)
    alice = station(client, d, OPERATOR_KEY, 241, 4)

    def set_and_answer(c: Client, value: float, expect: float) -> bool:
        """Whether `c` is answered with ANGLE_MAX = expect (a station of the same channel may
        also see the other's answer: the value is what tells them apart)."""
        mark = c.mark()
        c.send(M.MAVLink_param_set_message(*VEHICLE, b"ANGLE_MAX", value, M.MAV_PARAM_TYPE_INT16))
        return wait_for(c, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == "ANGLE_MAX"
                        and r.msg.param_value == expect, since=mark) is not None

    assert set_and_answer(alice, 3000, 3000)
    assert set_and_answer(viewer, 4500, 3000), "the observer is answered with the unchanged value"
    assert set_and_answer(alice, 3100, 3100), "the operator's PARAM_SET takes effect (after the denial)"
    mark = viewer.mark()
    viewer.send(M.MAVLink_param_request_read_message(*VEHICLE, b"ANGLE_MAX", -1))
    read = wait_for(viewer, lambda r: r.type == "PARAM_VALUE" and r.msg.param_value == 3100, since=mark)
    assert read is not None, "the observer reads parameters; 4500 was never set"


def test_observer_mission_count_denied_operator_accepted(daemon, client, tmp_path):
    d = roles_daemon(daemon, tmp_path)
    viewer = station(client, d, OBSERVER_KEY, 240, 3)
    alice = station(client, d, OPERATOR_KEY, 241, 4)
    mark = viewer.mark()
    viewer.send(M.MAVLink_mission_count_message(*VEHICLE, 3, 0))
    ack = wait_for(viewer, lambda r: r.type == "MISSION_ACK", since=mark)
    assert ack is not None and ack.msg.type == M.MAV_MISSION_DENIED
    mark = alice.mark()
    alice.send(M.MAVLink_mission_count_message(*VEHICLE, 3, 0))
    request = wait_for(alice, lambda r: r.type in ("MISSION_REQUEST_INT", "MISSION_REQUEST"), since=mark)
    assert request is not None, "the operator's upload starts"


def test_setup_signing_needs_admin(daemon, client, tmp_path):
    d = roles_daemon(daemon, tmp_path)
    alice = station(client, d, OPERATOR_KEY, 241, 4)
    root = station(client, d, ADMIN_KEY, 242, 5)
    new_key = hashlib.sha256(b"new").digest()
    before = d.stats("gcs")["denied"]
    alice.send(M.MAVLink_setup_signing_message(*VEHICLE, list(new_key), now_units()))
    assert command_result(alice, M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == M.MAV_RESULT_ACCEPTED
    assert d.stats("gcs")["denied"] == before + 1, "the operator's SETUP_SIGNING was denied"
    root.send(M.MAVLink_setup_signing_message(*VEHICLE, list(new_key), now_units()))
    # the admin's is taken: replies are now signed with the new key
    fresh = client(udp_url(d.port("gcs")), 243, 190)
    sign(fresh, new_key, link_id=6)  # only frames signed with the new key are read
    for _ in range(20):
        if command_result(fresh, M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) is not None:
            break
    else:
        raise AssertionError("the admin's SETUP_SIGNING was not taken")
