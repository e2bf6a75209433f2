"""The mqtt channel's configuration keys, and the pure parts of the channel (topics, frame headers)."""

from pathlib import Path
from textwrap import dedent

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.config import ConfigError, load_config, parse_config
from gcsd.config.mqtt import MqttConfig, parse_broker, route_capacity
from gcsd.links.mqtt import Topics, frame_source, frame_target_system, topic_source_sysid


def channel(extra: str) -> str:
    return "channels:\n  - name: fleet\n    type: mqtt\n" + "".join(f"    {line}\n" for line in dedent(extra).splitlines())


def parse(extra: str):
    return parse_config(channel(extra), "fleet.yaml").channels[0]


def problems(extra: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse_config(channel(extra), "fleet.yaml")
    return caught.value.problems


def test_every_key_is_optional_and_the_defaults_are_a_local_broker_vehicle_side():
    c = parse("")
    assert c.mqtt == MqttConfig()
    assert (c.mqtt.host, c.mqtt.port, c.mqtt.tls, c.mqtt.topic, c.mqtt.role) == ("127.0.0.1", 1883, False, "gcsd",
                                                                                   "vehicle")
    assert c.address is None and c.mqtt.sysids is None


def test_a_full_ground_side_channel():
    c = parse("""\
        broker: mqtts://broker.example.com
        topic: gcsd/fleet1
        role: ground
        sysids: [1, "10-12", 200]
        username: ops
        password_file: /etc/gcsd/mqtt.pass
        client_id: ground-1
        ca_file: /etc/gcsd/ca.pem
        cert_file: /etc/gcsd/client.pem
        key_file: /etc/gcsd/client.key
    """).mqtt
    assert (c.tls, c.host, c.port, c.topic, c.role) == (True, "broker.example.com", 8883, "gcsd/fleet1", "ground")
    assert c.sysids == frozenset({1, 10, 11, 12, 200})
    assert (c.username, c.password_file, c.client_id) == ("ops", "/etc/gcsd/mqtt.pass", "ground-1")
    assert (c.ca_file, c.cert_file, c.key_file) == ("/etc/gcsd/ca.pem", "/etc/gcsd/client.pem", "/etc/gcsd/client.key")


@pytest.mark.parametrize("text, sysids", [
    ("all", None), ("7", {7}), ('"1-3"', {1, 2, 3}), ("[5, 5, 6]", {5, 6}), ('["250-255"]', set(range(250, 256))),
])
def test_sysids_forms(text, sysids):
    got = parse(f"role: ground\nsysids: {text}").mqtt.sysids
    assert got == (None if sysids is None else frozenset(sysids))


@pytest.mark.parametrize("url, expected", [
    ("mqtt://10.0.0.5", (False, "10.0.0.5", 1883)),
    ("mqtt://broker:1999/", (False, "broker", 1999)),
    ("mqtts://[::1]:8884", (True, "::1", 8884)),
    ("mqtts://[fe80::1]", (True, "fe80::1", 8883)),
])
def test_broker_urls(url, expected):
    assert parse_broker(url) == expected


@pytest.mark.parametrize("extra, line, message", [
    ("broker: tcp://x:1883", 4, ("fleet.yaml:4: channels[0].broker: expected mqtt://HOST[:PORT] or mqtts://HOST[:PORT], "
                                "got 'tcp://x:1883'")),
    ("broker: mqtt://user:pw@x", 4, "credentials go in username and password_file"),
    ("broker: mqtt://x:70000", 4, "port must be 1..65535, got 70000"),
    ("broker: mqtt://::1:1883", 4, "an IPv6 address goes in brackets"),
    ("topic: gcsd/+/x", 4, "channels[0].topic: a topic prefix may not contain the wildcards"),
    ("topic: gcsd/", 4, "no empty levels"),
    ("role: gcs", 4, "channels[0].role: expected vehicle|ground, got 'gcs'"),
    ("sysids: all", 4, "channels[0].sysids: only used by role ground"),
    ("role: ground\nsysids: 256", 5, 'channels[0].sysids: expected all, a sysid 1..255, a range "A-B", or a list'),
    ("role: ground\nsysids: [1, '9-3']", 5, "channels[0].sysids[1]: expected all"),
    ("role: ground\nsysids: []", 5, "channels[0].sysids: expected all"),
    ("password_file: /p", 4, "channels[0].password_file: needs username"),
    ("ca_file: /ca.pem", 4, "channels[0].ca_file: only used with an mqtts:// broker"),
    ("broker: mqtts://x\nkey_file: /k", 5, "channels[0].key_file: needs cert_file"),
    ("address: 127.0.0.1:1883", 4, "channels[0].address: not used by mqtt channels"),
    ("device: /dev/ttyS0", 4, "channels[0].device: not used by mqtt channels"),
])
def test_bad_mqtt_keys_are_file_line_key_path_and_what(extra, line, message):
    found = problems(extra)
    assert len(found) == 1, found
    assert found[0].startswith(f"fleet.yaml:{line}: ") and message in found[0]


def test_mqtt_keys_on_another_channel_type_are_problems():
    text = "channels:\n  - name: gcs\n    type: udp-server\n    address: 127.0.0.1:14550\n    topic: gcsd/x\n"
    with pytest.raises(ConfigError) as caught:
        parse_config(text, "g.yaml")
    assert caught.value.problems == ["g.yaml:5: channels[0].topic: only used by mqtt channels"]


def test_route_table_has_room_for_a_fleet_per_mqtt_channel():
    assert route_capacity(["udp-server", "serial"], 20) == 20
    assert route_capacity(["udp-server", "mqtt"], 20) >= 20 + 255


# --- topics and frame headers (mqtt.py) ---------------------------------------------------------

def packed(msg, sysid=255, compid=190, v1=False) -> bytes:
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    return bytes(msg.pack(mav, force_mavlink1=v1))


@pytest.mark.parametrize("v1", [False, True])
def test_target_system_is_read_from_the_raw_header_in_both_versions(v1):
    param_set = M.MAVLink_param_set_message(42, 1, b"X", 1.0, M.MAV_PARAM_TYPE_REAL32)
    assert frame_target_system(packed(param_set, v1=v1)) == 42
    assert frame_target_system(packed(M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3), v1=v1)) == 0  # no target field
    assert frame_target_system(packed(M.MAVLink_command_long_message(0, 0, 400, 0, 1, 0, 0, 0, 0, 0, 0), v1=v1)) == 0
    assert frame_source(packed(param_set, 9, 191, v1=v1)) == (9, 191)


def test_unknown_message_ids_and_truncated_targets_are_broadcasts():
    unknown = bytes([0xFD, 1, 0, 0, 0, 9, 1, 0x39, 0x30, 0x00, 0x07, 0, 0])  # msgid 12345
    assert frame_target_system(unknown) == 0
    # MAVLink2 trims trailing zero bytes: a PARAM_REQUEST_LIST to system 0 component 0 has an empty payload
    trimmed = packed(M.MAVLink_param_request_list_message(0, 0))
    assert trimmed[1] == 1 and frame_target_system(trimmed) == 0


def test_topics():
    t = Topics("gcsd/fleet1")
    assert t.up(3, 1) == "gcsd/fleet1/up/3/1"
    assert (t.down(0), t.down(7)) == ("gcsd/fleet1/down/all", "gcsd/fleet1/down/7")
    assert t.ground_subscriptions(None) == ["gcsd/fleet1/up/+/+"]
    assert t.ground_subscriptions(frozenset({2, 1})) == ["gcsd/fleet1/up/1/+", "gcsd/fleet1/up/2/+"]
    assert t.vehicle_subscriptions({5}) == ["gcsd/fleet1/down/all", "gcsd/fleet1/down/5"]


FLEET = Path(__file__).resolve().parents[2] / "sitl" / "fleet"


@pytest.mark.parametrize(("topic", "sysid"), [("f/up/7/1", 7), ("a/b/up/255/190", 255), ("f/up/0/0", 0),
                                               ("f/up/007/1", None), ("f/up/256/1", None), ("f/up/x/1", None),
                                               ("f/up/+7/1", None), ("f/up/\u0667/1", None), ("f/up//1", None)])
def test_the_system_an_uplink_topic_names_is_read_only_as_gcsd_spells_it(topic, sysid):
    assert topic_source_sysid(topic) == sysid


@pytest.mark.parametrize("name", ["vehicles.yaml", "ground.yaml"])
def test_fleet_configurations_are_valid(name):
    config = load_config(FLEET / name)
    [mqtt] = [c.mqtt for c in config.channels if c.type == "mqtt"]
    assert mqtt.topic == "gcsd/fleet1" and mqtt.role == ("ground" if name == "ground.yaml" else "vehicle")
