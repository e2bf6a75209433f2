"""mavlink2rest's JSON forms, checked against the examples in its repository (README.md,
tests/run.py) and Cockpit's reader; SPEC.md pins bitmasks as {"bits": N}."""

import json
import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.api.http.mavjson import (
    BadMessage,
    UnknownMessage,
    message_json,
    parse_envelope,
    parse_message,
    template,
)
from gcsd.api.http.tree import MessageTree
from gcsd.wire.codec import FrameParser

# README.md, "GET /v1/helper/mavlink?name=HEARTBEAT", with base_mode in the {"bits": N} form SPEC pins
README_HEARTBEAT_TEMPLATE = {
    "header": {"system_id": 255, "component_id": 0, "sequence": 0},
    "message": {
        "type": "HEARTBEAT", "custom_mode": 0, "mavtype": {"type": "MAV_TYPE_GENERIC"},
        "autopilot": {"type": "MAV_AUTOPILOT_GENERIC"}, "base_mode": {"bits": 0},
        "system_status": {"type": "MAV_STATE_UNINIT"}, "mavlink_version": 3,
    },
}
# README.md, "?name=ATTITUDE"
README_ATTITUDE_TEMPLATE = {
    "header": {"system_id": 255, "component_id": 0, "sequence": 0},
    "message": {"type": "ATTITUDE", "time_boot_ms": 0, "roll": 0.0, "pitch": 0.0, "yaw": 0.0,
                "rollspeed": 0.0, "pitchspeed": 0.0, "yawspeed": 0.0},
}
# README.md, "Request vehicle to be armed"
README_ARM = {
    "header": {"system_id": 255, "component_id": 240, "sequence": 0},
    "message": {
        "type": "COMMAND_LONG", "param1": 1.0, "param2": 0.0, "param3": 0.0, "param4": 0.0, "param5": 0.0,
        "param6": 0.0, "param7": 0.0, "command": {"type": "MAV_CMD_COMPONENT_ARM_DISARM"},
        "target_system": 1, "target_component": 1, "confirmation": 1,
    },
}


def test_heartbeat_template_is_the_readme_example_with_bits():
    t = template("HEARTBEAT")
    assert t == {**README_HEARTBEAT_TEMPLATE, "message": {**README_HEARTBEAT_TEMPLATE["message"], "mavlink_version": 0}}
    assert list(t["message"]) == list(README_HEARTBEAT_TEMPLATE["message"])  # wire order, type first


def test_attitude_template_is_the_readme_example():
    assert template("ATTITUDE") == README_ATTITUDE_TEMPLATE
    assert list(template("ATTITUDE")["message"]) == list(README_ATTITUDE_TEMPLATE["message"])


def test_command_long_template_starts_with_the_first_mav_cmd():
    message = template("COMMAND_LONG")["message"]
    assert message["command"] == {"type": "MAV_CMD_NAV_WAYPOINT"}
    assert list(message) == ["type", "param1", "param2", "param3", "param4", "param5", "param6", "param7",
                             "command", "target_system", "target_component", "confirmation"]


def test_unknown_template_name_is_refused():
    with pytest.raises(UnknownMessage, match="Invalid message name"):
        template("NOT_A_MESSAGE")


def test_heartbeat_as_cockpit_reads_it():
    hb = M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0x81, 4, M.MAV_STATE_ACTIVE, 3)
    out = message_json(hb)
    assert out["mavtype"] == {"type": "MAV_TYPE_QUADROTOR"}
    assert out["autopilot"] == {"type": "MAV_AUTOPILOT_ARDUPILOTMEGA"}
    assert out["base_mode"]["bits"] & 128  # tests/run.py: vehicle_mode() & 128 is "armed"
    assert out["system_status"] == {"type": "MAV_STATE_ACTIVE"}
    assert "type" in out and out["type"] == "HEARTBEAT"


def test_every_field_named_type_is_mavtype():
    ack = M.MAVLink_mission_ack_message(1, 1, M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_TYPE_FENCE)
    out = message_json(ack)
    assert out["mavtype"] == {"type": "MAV_MISSION_ACCEPTED"}
    assert out["mission_type"] == {"type": "MAV_MISSION_TYPE_FENCE"}
    assert parse_message(out).type == M.MAV_MISSION_ACCEPTED


def test_sys_status_sensors_are_bitmasks():
    msg = M.MAVLink_sys_status_message(7, 3, 1, 500, 12000, 100, 80, 0, 0, 0, 0, 0, 0)
    out = message_json(msg)
    assert out["onboard_control_sensors_present"] == {"bits": 7}


def test_char_arrays_are_lists_of_characters_padded_with_nul():
    msg = M.MAVLink_param_value_message(b"SYSID_THISMAV", 1.0, M.MAV_PARAM_TYPE_INT32, 900, 3)
    out = message_json(msg)
    assert len(out["param_id"]) == 16
    assert "".join(out["param_id"]).replace("\0", "") == "SYSID_THISMAV"  # Cockpit's reader
    assert out["param_type"] == {"type": "MAV_PARAM_TYPE_INT32"}


def test_nan_is_null_and_unknown_enum_values_are_bare_numbers():
    msg = M.MAVLink_command_long_message(1, 1, 60999, 0, math.nan, 0, 0, 0, 0, 0, math.inf)
    out = message_json(msg)
    assert out["command"] == 60999 and out["param1"] is None and out["param7"] is None
    json.dumps(out, allow_nan=False)


def test_readme_arm_example_parses_to_command_long():
    header, msg = parse_envelope(README_ARM)
    assert (header.system_id, header.component_id, header.sequence) == (255, 240, 0)
    assert msg.get_type() == "COMMAND_LONG"
    assert (msg.command, msg.param1, msg.target_system, msg.confirmation) == (400, 1.0, 1, 1)


def test_written_json_reads_back_to_the_same_message():
    messages = [
        M.MAVLink_heartbeat_message(2, 3, 0x59, 4, 4, 3),
        M.MAVLink_param_set_message(1, 1, b"WPNAV_SPEED", 750.0, M.MAV_PARAM_TYPE_REAL32),
        M.MAVLink_statustext_message(M.MAV_SEVERITY_INFO, b"hello", 0, 0),
        M.MAVLink_set_position_target_local_ned_message(0, 1, 1, 1, 0x0DF8, 1, 2, 3, 0, 0, 0, 0, 0, 0, 0, 0),
        M.MAVLink_rc_channels_override_message(1, 1, *range(1000, 1018)),
    ]
    for msg in messages:
        again = parse_message(message_json(msg))
        assert again.pack(M.MAVLink(None)) == msg.pack(M.MAVLink(None)), msg.get_type()


@pytest.mark.parametrize("message,error", [
    ({"type": "COMMAND_LONG", "param1": "1"}, "COMMAND_LONG.param1: expected a number"),
    ({"type": "COMMAND_LONG", "target_system": 256}, "out of range"),
    ({"type": "COMMAND_LONG", "target_system": True}, "expected an integer"),
    ({"type": "COMMAND_LONG", "target_system": 1.5}, "expected an integer"),
    ({"type": "COMMAND_LONG", "command": {"type": "MAV_STATE_ACTIVE"}}, "not an entry of MAV_CMD"),
    ({"type": "COMMAND_LONG", "command": {"kind": 1}}, "expected"),
    ({"type": "COMMAND_LONG", "bogus": 1}, "has no field 'bogus'"),
    ({"type": "COMMAND_LONG", "param1": 1e39}, "not a finite float32"),
    ({"type": "HEARTBEAT", "base_mode": {"bits": -1}}, "out of range"),
    ({"type": "HEARTBEAT", "base_mode": "MAV_MODE_FLAG_NOPE"}, "not a flag of MAV_MODE_FLAG"),
    ({"type": "PARAM_SET", "param_id": "X" * 17}, "at most 16"),
    ({"type": "PARAM_SET", "param_id": [1.5]}, "one character"),
    ({"type": "RC_CHANNELS_OVERRIDE", "chan1_raw": []}, "expected an integer"),
])
def test_bad_values_name_the_field(message, error):
    with pytest.raises(BadMessage, match=error):
        parse_message(message)


def test_unknown_message_and_bad_envelopes():
    with pytest.raises(UnknownMessage):
        parse_message({"type": "NOPE"})
    with pytest.raises(UnknownMessage):
        parse_message({"param1": 1})
    for doc in ([], {"message": {"type": "PING"}}, {"header": {"system_id": 1}, "message": {}},
                {"header": {"system_id": 1, "component_id": 1}, "message": {"type": "PING"}, "x": 1}):
        with pytest.raises(BadMessage):
            parse_envelope(doc)


def test_other_accepted_forms():
    msg = parse_message({"type": "HEARTBEAT", "mavtype": "MAV_TYPE_GCS", "base_mode": "MAV_MODE_FLAG_SAFETY_ARMED | "
                         "MAV_MODE_FLAG_CUSTOM_MODE_ENABLED", "autopilot": 8})
    assert (msg.type, msg.base_mode, msg.autopilot) == (6, 129, 8)
    msg = parse_message({"type": "PARAM_REQUEST_READ", "param_id": list("RO_SPEED_LIM") + ["\0"] * 4,
                         "param_index": -1, "target_system": 1})
    assert msg.param_id == "RO_SPEED_LIM" or msg.param_id == b"RO_SPEED_LIM"


def test_tree_pretty_heartbeat_has_the_shape_tests_run_py_counts():
    tree = MessageTree()
    tree.update(1, 1, "HEARTBEAT", M.MAVLink_heartbeat_message(2, 3, 0x51, 4, 3, 3), 1000.0)
    doc = tree.document(["vehicles", "1", "components", "1", "messages", "HEARTBEAT"])
    assert json.dumps(doc, indent=2).count("\n") == 26  # mavlink2rest tests/run.py "Test pretty"


def test_tree_counts_and_frequency_and_times():
    tree = MessageTree()
    att = M.MAVLink_attitude_message(1, 0.5, 0.1, 0.2, 0, 0, 0)
    for i in range(21):
        tree.update(1, 1, "ATTITUDE", att, 1000.0 + i * 0.1)
    status = tree.document(["vehicles", "1", "components", "1", "messages", "ATTITUDE", "status", "time"])
    assert status["counter"] == 21
    assert status["frequency"] == pytest.approx(21 / 2.0)
    assert status["first_update"].startswith("1970-01-01") and status["first_update"][-6] in "+-"
    assert tree.document(["vehicles", "1", "components", "1", "messages", "ATTITUDE", "message", "roll"]) == 0.5
    assert tree.document(["vehicles", "1", "id"]) == 1
    whole = tree.document([])
    assert whole["vehicles"]["1"]["components"]["1"]["messages"]["ATTITUDE"]["message"]["type"] == "ATTITUDE"
    assert tree.document(["vehicles"]) == whole["vehicles"]


@pytest.mark.parametrize("path", [["nope"], ["vehicles", "2"], ["vehicles", "x"], ["vehicles", "1", "components", "9"],
                                  ["vehicles", "1", "components", "1", "messages", "GPS_RAW_INT"],
                                  ["vehicles", "1", "components", "1", "messages", "ATTITUDE", "message", "nope"],
                                  ["vehicles", "1", "id", "x"]])
def test_tree_unknown_paths_are_key_errors(path):
    tree = MessageTree()
    tree.update(1, 1, "ATTITUDE", FrameParser().feed(M.MAVLink_attitude_message(1, 0.5, 0.1, 0.2, 0, 0, 0).pack(M.MAVLink(None)))[0], 5.0)
    assert tree.document(["vehicles", "1", "components", "1", "messages", "ATTITUDE", "message", "roll"]) == 0.5
    with pytest.raises(KeyError):
        tree.document(path)


def test_tree_is_bounded_by_components():
    tree = MessageTree(max_components=3)
    for compid in range(5):
        tree.update(1, compid, "ATTITUDE", M.MAVLink_attitude_message(1, 0, 0, 0, 0, 0, 0), 1.0)
    assert len(tree.document(["vehicles", "1", "components"])) == 3
    assert tree.components_refused == 2


@pytest.mark.parametrize("name", sorted(cls.msgname for cls in M.mavlink_map.values()))
def test_every_template_reads_back_and_packs(name):
    doc = template(name)
    json.dumps(doc, allow_nan=False)
    header, msg = parse_envelope(doc)
    assert msg.get_type() == name and header.system_id == 255
    msg.pack(M.MAVLink(None))
    again = message_json(msg)
    assert parse_message(again).pack(M.MAVLink(None)) == msg.pack(M.MAVLink(None))


def test_cockpit_set_position_target_reads():
    # bluerobotics/cockpit src/libs/vehicle/ardupilot/ardupilot.ts: what it sends to change altitude
    cockpit = {"time_boot_ms": 0, "type": "SET_POSITION_TARGET_LOCAL_NED", "target_system": 1, "target_component": 1,
               "coordinate_frame": {"type": "MAV_FRAME_LOCAL_OFFSET_NED"}, "type_mask": {"bits": 0b0000111111111000},
               "x": 0, "y": 0, "z": -10, "vx": 0, "vy": 0, "vz": 0, "afx": 0, "afy": 0, "afz": 0, "yaw": 0, "yaw_rate": 0}
    msg = parse_message(cockpit)
    assert (msg.coordinate_frame, msg.type_mask, msg.z) == (M.MAV_FRAME_LOCAL_OFFSET_NED, 0x0FF8, -10.0)


def test_extension_fields_pymavlink_lacks_are_accepted_and_carried_on_the_wire():
    """Cockpit's TIMESYNC (issue 27): target_system and target_component follow tc1 and ts1 in
    the MAVLink 2 payload; pymavlink's own parser still reads the base fields."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    from gcsd.api.http.mavjson import parse_message

    msg = parse_message({"type": "TIMESYNC", "tc1": 0, "ts1": 99, "target_system": 1, "target_component": 190})
    frame = msg.pack(mavlink.MAVLink(None, 255, 240))
    assert frame[1] == 18 and frame[10 + 16:10 + 18] == bytes([1, 190])  # payload length, the extension bytes
    assert mavlink.MAVLink(None).parse_char(bytearray(frame)).ts1 == 99
    v1 = parse_message({"type": "TIMESYNC", "ts1": 5, "target_system": 1}).pack(
        mavlink.MAVLink(None, 255, 240), force_mavlink1=True)
    assert v1[1] == 16, "MAVLink 1 has no extension fields"
