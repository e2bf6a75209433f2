"""Authority (SPEC.md "Authority: who may do what, on every surface"): the one role table. Pure.

Three roles, each allowing what the one below allows and more:

- `observer`: telemetry and routed traffic, parameter reads, mission/fence/rally and log
  downloads, FTP reads, HTTP GETs, WebSocket receive;
- `operator`: also commands (COMMAND_LONG/INT, SET_MODE, MANUAL_CONTROL, RC_CHANNELS_OVERRIDE,
  SET_POSITION_TARGET_*, camera, gimbal, CAN), PARAM_SET, plan uploads and clears, FTP writes,
  HTTP POST/PUT;
- `admin`: also SETUP_SIGNING, STORAGE_FORMAT, LOG_ERASE, PREFLIGHT_STORAGE,
  PREFLIGHT_REBOOT_SHUTDOWN, SERIAL_CONTROL, key and channel changes.

`required(msgid, command, ftp_opcode)` is the role a frame needs; a message not in the table
needs OBSERVER (anyone who may be heard at all). A COMMAND_LONG/INT needs OPERATOR unless its
command is one of ADMIN_COMMANDS; FILE_TRANSFER_PROTOCOL needs OPERATOR for the opcodes that
write (FTP_WRITE_OPCODES), OBSERVER for reads. Roles are small integers so that a check is one
comparison: `allowed(role, needed)` is `role >= needed`.

`refusal(msgid)` is the protocol's answer to a denied frame, one table for every service:
COMMAND_ACK MAV_RESULT_DENIED, PARAM_VALUE with the unchanged value, MISSION_ACK
MAV_MISSION_DENIED, FTP NAK, none (dropped, counted) for the rest. `passphrase_key` is the key
QGroundControl and MAVProxy's `signing setup PASSPHRASE` derive: SHA-256 of the passphrase's
UTF-8 bytes.
"""

from __future__ import annotations

import hashlib

from pymavlink.dialects.v20 import ardupilotmega as M

OBSERVER, OPERATOR, ADMIN = 0, 1, 2
ROLE_NAMES = ("observer", "operator", "admin")
ROLES = {name: value for value, name in enumerate(ROLE_NAMES)}

# refusals: what a denied frame is answered with
REFUSE_COMMAND = "command_ack"  # COMMAND_ACK MAV_RESULT_DENIED
REFUSE_PARAM = "param_value"  # PARAM_VALUE with the unchanged value
REFUSE_MISSION = "mission_ack"  # MISSION_ACK MAV_MISSION_DENIED
REFUSE_FTP = "ftp_nak"  # FILE_TRANSFER_PROTOCOL NAK
REFUSE_DROP = None  # no reply in the protocol: dropped, counted `denied`

_OPERATOR_MESSAGES = (
    "COMMAND_LONG", "COMMAND_INT", "SET_MODE", "MANUAL_CONTROL", "RC_CHANNELS_OVERRIDE",
    "SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT", "SET_ATTITUDE_TARGET",
    "SET_ACTUATOR_CONTROL_TARGET", "SET_HOME_POSITION", "SET_GPS_GLOBAL_ORIGIN",
    "PARAM_SET", "PARAM_EXT_SET",
    "MISSION_COUNT", "MISSION_ITEM", "MISSION_ITEM_INT", "MISSION_CLEAR_ALL", "MISSION_SET_CURRENT",
    "MISSION_WRITE_PARTIAL_LIST",
    "GIMBAL_MANAGER_SET_ATTITUDE", "GIMBAL_MANAGER_SET_PITCHYAW", "GIMBAL_MANAGER_SET_MANUAL_CONTROL",
    "GIMBAL_DEVICE_SET_ATTITUDE", "MOUNT_CONFIGURE", "MOUNT_CONTROL", "DIGICAM_CONTROL",
    "DIGICAM_CONFIGURE",
    "CAN_FRAME", "CANFD_FRAME", "CAN_FILTER_MODIFY",
    "GPS_INJECT_DATA", "GPS_RTCM_DATA", "LANDING_TARGET", "FENCE_POINT", "RALLY_POINT",
)
_ADMIN_MESSAGES = ("SETUP_SIGNING", "LOG_ERASE", "SERIAL_CONTROL")
_ADMIN_COMMANDS = ("MAV_CMD_STORAGE_FORMAT", "MAV_CMD_PREFLIGHT_STORAGE", "MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN")


def _ids(prefix: str, names: tuple[str, ...]) -> dict[str, int]:
    """The dialect's number for each name (a name this pymavlink lacks is skipped)."""
    return {name: getattr(M, prefix + name) for name in names if hasattr(M, prefix + name)}


MESSAGE_ROLES: dict[int, int] = {
    **{msgid: OPERATOR for msgid in _ids("MAVLINK_MSG_ID_", _OPERATOR_MESSAGES).values()},
    **{msgid: ADMIN for msgid in _ids("MAVLINK_MSG_ID_", _ADMIN_MESSAGES).values()},
}
MESSAGE_NAMES: dict[int, str] = {v: k for k, v in _ids("MAVLINK_MSG_ID_", _OPERATOR_MESSAGES + _ADMIN_MESSAGES).items()}
ADMIN_COMMANDS = frozenset(_ids("", _ADMIN_COMMANDS).values())
COMMAND_IDS = frozenset({M.MAVLINK_MSG_ID_COMMAND_LONG, M.MAVLINK_MSG_ID_COMMAND_INT})
FTP = M.MAVLINK_MSG_ID_FILE_TRANSFER_PROTOCOL
# MAVLink FTP opcodes that change the vehicle's files (REFERENCE.md, the FTP section)
FTP_CREATE_FILE, FTP_WRITE_FILE, FTP_REMOVE_FILE, FTP_CREATE_DIRECTORY = 6, 7, 8, 9
FTP_REMOVE_DIRECTORY, FTP_OPEN_FILE_WO, FTP_TRUNCATE_FILE, FTP_RENAME = 10, 11, 12, 13
FTP_WRITE_OPCODES = frozenset({FTP_CREATE_FILE, FTP_WRITE_FILE, FTP_REMOVE_FILE, FTP_CREATE_DIRECTORY,
                               FTP_REMOVE_DIRECTORY, FTP_OPEN_FILE_WO, FTP_TRUNCATE_FILE, FTP_RENAME})
FTP_OPCODE_INDEX = 3  # in the payload: seq (2 bytes), session, opcode

REFUSALS: dict[int, str | None] = {
    M.MAVLINK_MSG_ID_COMMAND_LONG: REFUSE_COMMAND, M.MAVLINK_MSG_ID_COMMAND_INT: REFUSE_COMMAND,
    M.MAVLINK_MSG_ID_PARAM_SET: REFUSE_PARAM,
    M.MAVLINK_MSG_ID_MISSION_COUNT: REFUSE_MISSION, M.MAVLINK_MSG_ID_MISSION_ITEM: REFUSE_MISSION,
    M.MAVLINK_MSG_ID_MISSION_ITEM_INT: REFUSE_MISSION, M.MAVLINK_MSG_ID_MISSION_CLEAR_ALL: REFUSE_MISSION,
    M.MAVLINK_MSG_ID_MISSION_WRITE_PARTIAL_LIST: REFUSE_MISSION,
    FTP: REFUSE_FTP,
}

# HTTP: what a request needs
HTTP_READ_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})


def role_name(role: int) -> str:
    return ROLE_NAMES[role]


def needs_decoding(msgid: int) -> bool:
    """Whether the role a frame needs depends on its payload (a command or an FTP opcode)."""
    return msgid in COMMAND_IDS or msgid == FTP


def required(msgid: int, command: int | None = None, ftp_opcode: int | None = None) -> int:
    """The least role that may send this message (a command's id / an FTP opcode where it matters)."""
    if msgid in COMMAND_IDS:
        return ADMIN if command in ADMIN_COMMANDS else OPERATOR
    if msgid == FTP:
        return OPERATOR if ftp_opcode in FTP_WRITE_OPCODES else OBSERVER
    return MESSAGE_ROLES.get(msgid, OBSERVER)


def required_for_frame(msgid: int, msg) -> int:
    """`required` for a decoded message (None when not decoded: the message's role alone, and a
    payload-dependent message is taken at its highest: ADMIN for a command, OPERATOR for FTP)."""
    if msgid in COMMAND_IDS:
        return required(msgid, None if msg is None else msg.command) if msg is not None else ADMIN
    if msgid == FTP:
        if msg is None:
            return OPERATOR
        payload = msg.payload
        return required(msgid, ftp_opcode=payload[FTP_OPCODE_INDEX] if len(payload) > FTP_OPCODE_INDEX else None)
    return MESSAGE_ROLES.get(msgid, OBSERVER)


def allowed(role: int, needed: int) -> bool:
    return role >= needed


def refusal(msgid: int) -> str | None:
    """How the protocol says no to this message (REFUSE_*; None: no answer, dropped)."""
    return REFUSALS.get(msgid, REFUSE_DROP)


def http_required(method: str) -> int:
    """An HTTP request's need: reads are OBSERVER's, POST/PUT/DELETE (and WebSocket sends) OPERATOR's."""
    return OBSERVER if method.upper() in HTTP_READ_METHODS else OPERATOR


def passphrase_key(passphrase: str) -> bytes:
    """The 32-byte key QGroundControl and MAVProxy (`signing setup PASSPHRASE`) derive."""
    return hashlib.sha256(passphrase.encode("utf-8")).digest()


def table() -> list[tuple[str, str]]:
    """(what, least role) rows, for docs/authority.md and `gcsd keys list --table`."""
    rows = [(name, role_name(MESSAGE_ROLES[msgid])) for name, msgid in sorted((n, i) for i, n in MESSAGE_NAMES.items())]
    rows += [(f"COMMAND_LONG/INT {name}", "admin") for name in _ADMIN_COMMANDS]
    rows += [("COMMAND_LONG/INT (any other command)", "operator"),
             ("FILE_TRANSFER_PROTOCOL write opcodes", "operator"),
             ("FILE_TRANSFER_PROTOCOL reads", "observer"),
             ("HTTP GET, WebSocket receive", "observer"), ("HTTP POST/PUT/DELETE, WebSocket send", "operator"),
             ("any other message (telemetry, requests, reads)", "observer")]
    return rows


FTP_NAK = 129  # MAVLink FTP's NAK opcode
FTP_ERROR_FAIL = 1


def refusal_message(kind: str | None, msg, sysid: int, compid: int, param=None):
    """The protocol's refusal of a denied, decoded message from (sysid, compid), or None (no
    answer in the protocol, or nothing to answer with). `param(name) -> PARAM_VALUE | None`
    gives the unchanged value for a denied PARAM_SET."""
    if msg is None or kind is None:
        return None
    if kind == REFUSE_COMMAND:
        return M.MAVLink_command_ack_message(msg.command, M.MAV_RESULT_DENIED, 0, 0, sysid, compid)
    if kind == REFUSE_MISSION:
        return M.MAVLink_mission_ack_message(sysid, compid, M.MAV_MISSION_DENIED, getattr(msg, "mission_type", 0))
    if kind == REFUSE_PARAM:
        name = msg.param_id.decode("ascii", "replace") if isinstance(msg.param_id, bytes) else msg.param_id
        return None if param is None else param(name.rstrip("\0"))
    if kind == REFUSE_FTP:
        request = bytes(msg.payload)
        seq = (int.from_bytes(request[0:2], "little") + 1) & 0xFFFF
        header = seq.to_bytes(2, "little") + bytes((request[2], FTP_NAK, 1, request[3], 0, 0)) + bytes(4)
        payload = header + bytes((FTP_ERROR_FAIL,))
        return M.MAVLink_file_transfer_protocol_message(msg.target_network, sysid, compid,
                                                        list(payload.ljust(251, b"\0")))
    return None
