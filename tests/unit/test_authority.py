"""The role table (routing/authority.py) and its configuration (config/authority.py)."""

from __future__ import annotations

import hashlib

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.config import ConfigError, load_config
from gcsd.config.authority import NamedKey, read_key
from gcsd.routing import authority as A


def test_roles_are_ordered():
    assert A.OBSERVER < A.OPERATOR < A.ADMIN
    assert [A.ROLES[n] for n in ("observer", "operator", "admin")] == [A.OBSERVER, A.OPERATOR, A.ADMIN]


@pytest.mark.parametrize(("msgid", "command", "needed"), [
    (M.MAVLINK_MSG_ID_HEARTBEAT, None, A.OBSERVER),
    (M.MAVLINK_MSG_ID_PARAM_REQUEST_READ, None, A.OBSERVER),
    (M.MAVLINK_MSG_ID_MISSION_REQUEST_LIST, None, A.OBSERVER),
    (M.MAVLINK_MSG_ID_PARAM_SET, None, A.OPERATOR),
    (M.MAVLINK_MSG_ID_MISSION_COUNT, None, A.OPERATOR),
    (M.MAVLINK_MSG_ID_SET_MODE, None, A.OPERATOR),
    (M.MAVLINK_MSG_ID_RC_CHANNELS_OVERRIDE, None, A.OPERATOR),
    (M.MAVLINK_MSG_ID_COMMAND_LONG, M.MAV_CMD_COMPONENT_ARM_DISARM, A.OPERATOR),
    (M.MAVLINK_MSG_ID_COMMAND_INT, M.MAV_CMD_DO_REPOSITION, A.OPERATOR),
    (M.MAVLINK_MSG_ID_COMMAND_LONG, M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, A.ADMIN),
    (M.MAVLINK_MSG_ID_COMMAND_LONG, M.MAV_CMD_STORAGE_FORMAT, A.ADMIN),
    (M.MAVLINK_MSG_ID_SETUP_SIGNING, None, A.ADMIN),
    (M.MAVLINK_MSG_ID_LOG_ERASE, None, A.ADMIN),
    (M.MAVLINK_MSG_ID_SERIAL_CONTROL, None, A.ADMIN),
])
def test_required_role(msgid, command, needed):
    assert A.required(msgid, command) == needed


def test_ftp_reads_are_observers_writes_operators():
    assert A.required(A.FTP, ftp_opcode=5) == A.OBSERVER  # ReadFile
    assert A.required(A.FTP, ftp_opcode=15) == A.OBSERVER  # BurstReadFile
    for opcode in (6, 7, 8, 9, 10, 11, 12, 13):
        assert A.required(A.FTP, ftp_opcode=opcode) == A.OPERATOR


def test_required_for_a_decoded_frame():
    arm = M.MAVLink_command_long_message(1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    assert A.required_for_frame(arm.id, arm) == A.OPERATOR
    assert A.required_for_frame(arm.id, None) == A.ADMIN  # undecoded: the highest it could need
    write = M.MAVLink_file_transfer_protocol_message(0, 1, 1, [0, 0, 0, 7] + [0] * 247)
    read = M.MAVLink_file_transfer_protocol_message(0, 1, 1, [0, 0, 0, 5] + [0] * 247)
    assert A.required_for_frame(write.id, write) == A.OPERATOR
    assert A.required_for_frame(read.id, read) == A.OBSERVER


def test_one_refusal_table():
    assert A.refusal(M.MAVLINK_MSG_ID_COMMAND_LONG) == A.REFUSE_COMMAND
    assert A.refusal(M.MAVLINK_MSG_ID_PARAM_SET) == A.REFUSE_PARAM
    assert A.refusal(M.MAVLINK_MSG_ID_MISSION_COUNT) == A.REFUSE_MISSION
    assert A.refusal(A.FTP) == A.REFUSE_FTP
    assert A.refusal(M.MAVLINK_MSG_ID_SET_MODE) is A.REFUSE_DROP


def test_http_methods():
    assert A.http_required("GET") == A.OBSERVER
    assert A.http_required("post") == A.OPERATOR
    assert A.http_required("PUT") == A.OPERATOR


def test_passphrase_key_is_mavproxys():
    # MAVProxy's signing setup: hashlib.sha256(passphrase.encode('utf-8')).digest()
    assert A.passphrase_key("secret") == hashlib.sha256(b"secret").digest()
    assert len(A.passphrase_key("x")) == 32


def test_the_table_names_every_admin_action():
    rows = dict(A.table())
    assert rows["SETUP_SIGNING"] == "admin" and rows["PARAM_SET"] == "operator"


def _config(tmp_path, text):
    path = tmp_path / "gcsd.yaml"
    path.write_text(text)
    return load_config(path)


def test_defaults_keep_todays_behaviour(tmp_path):
    config = _config(tmp_path, "channels:\n  - {name: a, type: udp-server, address: 127.0.0.1:14550}\n")
    assert config.signing.keys == () and config.http.tokens == ()
    assert config.channels[0].role == "admin"
    assert config.http.anonymous_role == "operator"


def test_keys_tokens_and_roles_read(tmp_path):
    config = _config(tmp_path, """
signing:
  require: true
  keys:
    - {name: alice-qgc, key_file: keys/alice.key, role: operator}
    - {name: lte-viewer, passphrase_file: keys/viewer.txt, role: observer}
channels:
  - {name: lan, type: udp-server, address: 0.0.0.0:14551, role: observer}
  - {name: m, type: mqtt, role: ground}
http:
  tokens:
    - {name: dashboard, token_file: tokens/dash.txt, role: observer}
""")
    assert [(k.name, k.role) for k in config.signing.keys] == [("alice-qgc", "operator"), ("lte-viewer", "observer")]
    assert config.channels[0].role == "observer"
    assert config.channels[1].mqtt.role == "ground" and config.channels[1].role == "admin"
    assert [(t.name, t.role) for t in config.http.tokens] == [("dashboard", "observer")]
    assert config.http.anonymous_role == "observer"  # signing.require: not armed by curl


def test_bad_values_name_file_line_and_key(tmp_path):
    with pytest.raises(ConfigError) as error:
        _config(tmp_path, """signing:
  keys:
    - {name: a, key_file: k, role: boss}
    - {name: a, key_file: k, role: observer}
    - {name: b, role: observer}
    - {name: "c d", key_file: k, passphrase_file: p, role: admin}
channels:
  - {name: lan, type: udp-server, address: 127.0.0.1:14551, role: pilot}
http:
  anonymous_role: everyone
  tokens:
    - {name: t}
""")
    text = "\n".join(error.value.problems)
    assert "gcsd.yaml:3: signing.keys[0].role: expected observer|operator|admin, got 'boss'" in text
    assert "gcsd.yaml:4: signing.keys[1].name: duplicate key name 'a'" in text
    assert "gcsd.yaml:5: signing.keys[2]" in text and "exactly one of key_file and passphrase_file" in text
    assert "signing.keys[3].name: a key name is" in text
    assert "gcsd.yaml:8: channels[0].role: expected observer|operator|admin, got 'pilot'" in text
    assert "http.anonymous_role: expected observer|operator|admin, got 'everyone'" in text
    assert "http.tokens[0].token_file: required for every token" in text


def test_key_files(tmp_path):
    (tmp_path / "a.key").write_text("ab" * 32 + "\n")
    (tmp_path / "p.txt").write_text("my passphrase\n")
    (tmp_path / "short.key").write_text("abcd\n")
    resolve = tmp_path.joinpath
    assert read_key(NamedKey("a", "operator", key_file="a.key"), resolve) == bytes([0xAB]) * 32
    assert read_key(NamedKey("p", "observer", passphrase_file="p.txt"), resolve) == A.passphrase_key("my passphrase")
    with pytest.raises(ValueError, match="got 4 characters"):
        read_key(NamedKey("s", "observer", key_file="short.key"), resolve)
