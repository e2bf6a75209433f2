"""QGroundControl's connect sequence, replayed step by step against the real daemon with pymavlink.

The steps and their order are QGroundControl's (HTRamsey/qgroundcontrol, upstream master 2026-02:
MultiVehicleManager, APMFirmwarePlugin::initializeStreamRates, InitialConnectStateMachine,
FTPManager, PlanManager; summarised in ../shared/QGC.md), sent as QGroundControl sends them
(sysid 255, compid 190), each step's answer asserted:

 - its HEARTBEAT; the vehicle's HEARTBEAT from compid 1 (ArduPilot, quadrotor);
 - REQUEST_DATA_STREAM for RAW_SENSORS 2, EXTENDED_STATUS 2, RC_CHANNELS 2, POSITION 3, EXTRA1 10,
   EXTRA2 10, EXTRA3 3 Hz, then SET_MESSAGE_INTERVAL HOME_POSITION and EXTENDED_SYS_STATE 1 s;
 - 0: REQUEST_MESSAGE(AUTOPILOT_VERSION): ACCEPTED, then the message within 1 s: ArduPilot 4.6
   official with a git hash (QGC picks its 4.6 parameter metadata from it) and the capabilities
   QGC assumes for ArduPilot (MAVLINK2, MISSION_INT, COMMAND_INT, MISSION_FENCE, MISSION_RALLY)
   plus FTP (QGC downloads parameters over FTP only then);
 - 1: REQUEST_MESSAGE(AVAILABLE_MODES, param2 1), then each further index up to number_modes: each
   ACCEPTED and the mode within 1 s (ArduPilot's send_available_mode: non-standard modes, custom
   mode number and name), which QGC's StandardModes turns into its mode list;
 - 2: REQUEST_MESSAGE(COMPONENT_METADATA), then (COMPONENT_INFORMATION): not ACCEPTED (ArduPilot
   has neither; QGC skips the component metadata);
 - 3: FTP OpenFileRO "@PARAM/param.pck", BurstReadFile to the end (ReadFile for any gap),
   TerminateSession; decoded with MAVProxy's param.pck decoder: num_params == total_params == the
   PARAM_VALUE count, and the parameters QGroundControl's ArduCopter setup pages read are there;
 - 4-6: MISSION_REQUEST_LIST for the mission (home as item 0, read with MISSION_REQUEST_INT and
   acknowledged), fence and rally (empty);
 - then, what QGC shows: "Ready to fly" (SYS_STATUS PREARM_CHECK enabled and healthy) and the
   streams it asked for at their rates, HOME_POSITION and EXTENDED_SYS_STATE at 1 Hz.
"""

from __future__ import annotations

import struct
import time

import pytest
from pymavlink.dialects.v20 import all as ALL

from .helpers import VEHICLE, M, is_ack, pump, rate_hz, wait_for

param_ftp = pytest.importorskip("MAVProxy.modules.lib.param_ftp", reason="MAVProxy (a test extra) decodes param.pck")

FTP_HEADER = struct.Struct("<HBBBBBxI")  # seq, session, opcode, size, req_opcode, burst_complete, offset
OPEN_FILE_RO, READ_FILE, BURST_READ_FILE, TERMINATE_SESSION, FTP_ACK, FTP_NAK = 4, 5, 15, 1, 128, 129
STREAMS = ((M.MAV_DATA_STREAM_RAW_SENSORS, 2), (M.MAV_DATA_STREAM_EXTENDED_STATUS, 2),
           (M.MAV_DATA_STREAM_RC_CHANNELS, 2), (M.MAV_DATA_STREAM_POSITION, 3), (M.MAV_DATA_STREAM_EXTRA1, 10),
           (M.MAV_DATA_STREAM_EXTRA2, 10), (M.MAV_DATA_STREAM_EXTRA3, 3))
AVAILABLE_MODES, COMPONENT_INFORMATION, COMPONENT_METADATA = 435, 395, 397
QGC_COPTER_PARAMS = (  # read by name on QGroundControl's ArduCopter setup pages
    "FRAME_CLASS", "FRAME_TYPE", "FLTMODE1", "FLTMODE6", "FLTMODE_CH", "RCMAP_ROLL", "RCMAP_THROTTLE", "RC1_MIN",
    "RC1_TRIM", "INS_ACCOFFS_X", "COMPASS_DEV_ID", "COMPASS_OFS2_X", "COMPASS_USE", "BATT_MONITOR", "BATT_CAPACITY",
    "FS_THR_ENABLE", "FS_THR_VALUE", "FS_OPTIONS", "ATC_RAT_RLL_P", "MOT_SPIN_ARM", "SYSID_THISMAV", "ARMING_CHECK",
    "DISARM_DELAY", "PILOT_TKOFF_ALT", "COMPASS_LEARN", "COMPASS_CAL_FIT",
)


def _request_message(gcs, msgid: int, param2: float = 0.0):
    mark = gcs.mark()
    gcs.command_long(M.MAV_CMD_REQUEST_MESSAGE, msgid, param2)
    ack = wait_for(gcs, is_ack(M.MAV_CMD_REQUEST_MESSAGE), 3.0, since=mark)  # QGC's ack timeout
    assert ack is not None, f"no COMMAND_ACK for REQUEST_MESSAGE({msgid})"
    return ack, mark


def _ftp(gcs, seq: int, opcode: int, session: int = 0, size: int = 0, offset: int = 0, data: bytes = b""):
    payload = FTP_HEADER.pack(seq, session, opcode, size, 0, 0, offset) + data
    gcs.send(M.MAVLink_file_transfer_protocol_message(0, *VEHICLE, payload + bytes(251 - len(payload))))


def _ftp_replies(gcs, since: int):
    out = []
    for r in gcs.since(since, "FILE_TRANSFER_PROTOCOL"):
        raw = bytes(r.msg.payload)
        seq, session, opcode, size, req, burst_complete, offset = FTP_HEADER.unpack_from(raw)
        out.append((seq, session, opcode, size, req, burst_complete, offset, raw[12:12 + size]))
    return out


def _download_param_pck(gcs) -> bytes:
    mark = gcs.mark()
    _ftp(gcs, 1, OPEN_FILE_RO, size=len(b"@PARAM/param.pck"), data=b"@PARAM/param.pck")
    opened = wait_for(gcs, lambda r: r.type == "FILE_TRANSFER_PROTOCOL", 1.0, since=mark)  # QGC: 1 s
    assert opened is not None
    _, session, opcode, size, req, _, _, data = _ftp_replies(gcs, mark)[0]
    assert (opcode, req, size) == (FTP_ACK, OPEN_FILE_RO, 4), "OpenFileRO not acknowledged with the file size"
    length = struct.unpack("<I", data)[0]
    chunks: dict[int, bytes] = {}
    mark = gcs.mark()
    _ftp(gcs, 2, BURST_READ_FILE, session=session, size=239)
    deadline = time.monotonic() + 5.0
    done = False
    while not done and time.monotonic() < deadline:
        pump([gcs], 0.05)
        for _, _, opcode, _, req, burst_complete, offset, data in _ftp_replies(gcs, mark):
            if opcode == FTP_ACK and req == BURST_READ_FILE:
                chunks[offset] = data
                done = done or bool(burst_complete)
            elif opcode == FTP_NAK and req == BURST_READ_FILE:
                done = True  # EOF
    got = bytearray()
    seq = 3
    while len(got) < length:  # gap fill as QGC's FTPManager does
        if len(got) in chunks:
            got += chunks[len(got)]
            continue
        mark = gcs.mark()
        _ftp(gcs, seq, READ_FILE, session=session, size=239, offset=len(got))
        seq += 1
        assert wait_for(gcs, lambda r: r.type == "FILE_TRANSFER_PROTOCOL", 1.0, since=mark)
        reply = _ftp_replies(gcs, mark)[0]
        assert reply[2] == FTP_ACK, f"ReadFile at {len(got)} refused"
        chunks[reply[6]] = reply[7]
    mark = gcs.mark()
    _ftp(gcs, seq, TERMINATE_SESSION, session=session)
    assert wait_for(gcs, lambda r: r.type == "FILE_TRANSFER_PROTOCOL", 1.0, since=mark)
    return bytes(got[:length])


def _mission_list(gcs, mission_type: int) -> int:
    mark = gcs.mark()
    gcs.send(M.MAVLink_mission_request_list_message(*VEHICLE, mission_type))
    count = wait_for(gcs, lambda r: r.type == "MISSION_COUNT" and r.msg.mission_type == mission_type, 1.5, since=mark)
    assert count is not None, f"no MISSION_COUNT for mission type {mission_type}"
    for seq in range(count.msg.count):
        mark = gcs.mark()
        gcs.send(M.MAVLink_mission_request_int_message(*VEHICLE, seq, mission_type))
        item = wait_for(gcs, lambda r, s=seq: r.type == "MISSION_ITEM_INT" and r.msg.seq == s, 1.5, since=mark)
        assert item is not None, f"no MISSION_ITEM_INT {seq} of mission type {mission_type}"
    if count.msg.count:
        gcs.send(M.MAVLink_mission_ack_message(*VEHICLE, M.MAV_MISSION_ACCEPTED, mission_type))
    return count.msg.count


def test_qgroundcontrol_connect_sequence_step_by_step(daemon, client):
    d = daemon({"channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]})
    gcs = client(f"udpout:127.0.0.1:{d.port('gcs')}")
    gcs.heartbeat()
    hb = wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE, 3.0)
    assert hb is not None
    assert (hb.msg.autopilot, hb.msg.type) == (M.MAV_AUTOPILOT_ARDUPILOTMEGA, M.MAV_TYPE_QUADROTOR)

    # APMFirmwarePlugin::initializeStreamRates
    for stream, hz in STREAMS:
        gcs.send(M.MAVLink_request_data_stream_message(*VEHICLE, stream, hz, 1))
    for msgid in (M.MAVLINK_MSG_ID_HOME_POSITION, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE):
        mark = gcs.mark()
        gcs.command_long(M.MAV_CMD_SET_MESSAGE_INTERVAL, msgid, 1_000_000)
        ack = wait_for(gcs, is_ack(M.MAV_CMD_SET_MESSAGE_INTERVAL), 3.0, since=mark)
        assert ack is not None and ack.msg.result == M.MAV_RESULT_ACCEPTED

    # 0: AUTOPILOT_VERSION
    ack, mark = _request_message(gcs, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert ack.msg.result == M.MAV_RESULT_ACCEPTED
    version = wait_for(gcs, lambda r: r.type == "AUTOPILOT_VERSION", 1.0, since=mark)
    assert version is not None, "AUTOPILOT_VERSION did not follow the ACCEPTED ack within 1 s"
    v = version.msg
    major, minor, patch, kind = (v.flight_sw_version >> 24) & 0xFF, (v.flight_sw_version >> 16) & 0xFF, \
        (v.flight_sw_version >> 8) & 0xFF, v.flight_sw_version & 0xFF
    assert (major, minor, kind) == (4, 6, M.FIRMWARE_VERSION_TYPE_OFFICIAL), (major, minor, patch, kind)
    assert any(v.flight_custom_version), "no git hash in flight_custom_version"
    for cap in (M.MAV_PROTOCOL_CAPABILITY_MAVLINK2, M.MAV_PROTOCOL_CAPABILITY_MISSION_INT,
                M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT, M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE,
                M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY, M.MAV_PROTOCOL_CAPABILITY_FTP,
                M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT, M.MAV_PROTOCOL_CAPABILITY_COMPASS_CALIBRATION):
        assert v.capabilities & cap, f"capability {cap} missing"

    # 1: standard modes, as QGC's StandardModes: index 1, then every other index up to number_modes
    modes = {}
    index, count = 1, 1
    while index <= count:
        ack, mark = _request_message(gcs, AVAILABLE_MODES, index)
        assert ack.msg.result == M.MAV_RESULT_ACCEPTED, f"AVAILABLE_MODES {index} refused"
        got = wait_for(gcs, lambda r: r.type == f"UNKNOWN_{AVAILABLE_MODES}", 1.0, since=mark)
        assert got is not None, f"AVAILABLE_MODES {index} did not follow the ACCEPTED ack within 1 s"
        m = ALL.MAVLink(None).parse_buffer(got.raw)[0]  # newer than the ardupilotmega dialect
        assert m.mode_index == index and m.standard_mode == ALL.MAV_STANDARD_MODE_NON_STANDARD
        count = m.number_modes
        modes[m.custom_mode] = m.mode_name
        index += 1
    assert len(modes) == count > 10
    assert {modes[0], modes[4], modes[5], modes[6]} == {"STABILIZE", "GUIDED", "LOITER", "RTL"}
    # 2: component metadata, then component information
    for msgid in (COMPONENT_METADATA, COMPONENT_INFORMATION):
        ack, _ = _request_message(gcs, msgid)
        assert ack.msg.result != M.MAV_RESULT_ACCEPTED, f"REQUEST_MESSAGE({msgid}) accepted"

    # 3: parameters over FTP, as QGC's _tryftp
    pck = _download_param_pck(gcs)
    decoded = param_ftp.ftp_param_decode(pck)
    assert decoded is not None and decoded.params
    magic, num_params, total_params = struct.unpack_from("<HHH", pck)
    assert magic in (0x671B, 0x671C) and num_params == total_params == len(decoded.params)
    names = {name.decode() for name, _, _ in decoded.params}
    missing = [name for name in QGC_COPTER_PARAMS if name not in names]
    assert not missing, f"parameters QGroundControl's setup pages read are missing: {missing}"
    mark = gcs.mark()
    gcs.send(M.MAVLink_param_request_read_message(*VEHICLE, b"", 0))
    first = wait_for(gcs, lambda r: r.type == "PARAM_VALUE", 3.0, since=mark)
    assert first is not None and first.msg.param_count == total_params

    # 4-6: mission (home is item 0), fence, rally
    assert _mission_list(gcs, M.MAV_MISSION_TYPE_MISSION) >= 1
    assert _mission_list(gcs, M.MAV_MISSION_TYPE_FENCE) == 0
    assert _mission_list(gcs, M.MAV_MISSION_TYPE_RALLY) == 0

    # what QGC then shows: Ready to fly, and the streams it asked for
    mark = gcs.mark()
    pump([gcs], 3.0)
    status = gcs.since(mark, "SYS_STATUS")
    assert status, "no SYS_STATUS"
    s = status[-1].msg
    assert s.onboard_control_sensors_enabled & M.MAV_SYS_STATUS_PREARM_CHECK
    assert s.onboard_control_sensors_health & M.MAV_SYS_STATUS_PREARM_CHECK, "QGC would say Not Ready To Fly"
    rates = {name: rate_hz([r for r in gcs.since(mark, name) if r.src == VEHICLE])
             for name in ("ATTITUDE", "GLOBAL_POSITION_INT", "SYS_STATUS", "HOME_POSITION", "EXTENDED_SYS_STATE",
                          "BATTERY_STATUS")}
    assert rates["ATTITUDE"] == pytest.approx(10, rel=0.3), rates
    assert rates["GLOBAL_POSITION_INT"] == pytest.approx(3, rel=0.3), rates
    assert rates["SYS_STATUS"] == pytest.approx(2, rel=0.3), rates
    assert rates["HOME_POSITION"] == pytest.approx(1, rel=0.3), rates
    assert rates["EXTENDED_SYS_STATE"] == pytest.approx(1, rel=0.3), rates
    assert gcs.since(mark, "BATTERY_STATUS"), "no BATTERY_STATUS: QGC would re-send its stream requests"
