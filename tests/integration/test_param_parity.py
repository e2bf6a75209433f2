"""ArduPilot's parameter set over the wire, through the real daemon: the PARAM_REQUEST_LIST answer
of a copter, plane and rover is the vehicle type's set (params/data/, checked against the SITL
capture in tests/unit/test_param_parity.py) in names, order, types and values; @PARAM/param.pck
over MAVLink FTP, decoded by MAVProxy's own decoder, is the same list; the banner and
AUTOPILOT_VERSION report the release the names belong to (ArduPilot 4.6.3, official)."""

from __future__ import annotations

import struct
import time

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.config import DEFAULT_STREAM_RATES_HZ
from gcsd.vehicle.ftp.protocol import Op, Payload
from gcsd.vehicle.params import ParamStore, as_float
from gcsd.vehicle.types import VEHICLE_TYPES, vehicle_params

from .helpers import VEHICLE, download_params, is_type, pump, udp_channel, udp_url, wait_for

param_ftp = pytest.importorskip("MAVProxy.modules.lib.param_ftp")

COUNTED = {"STAT_BOOTCNT", "STAT_RUNTIME"}  # maintained by the daemon while it runs
PCK_TYPE = {1: M.MAV_PARAM_TYPE_INT8, 2: M.MAV_PARAM_TYPE_INT16, 3: M.MAV_PARAM_TYPE_INT32, 4: M.MAV_PARAM_TYPE_REAL32}


def expected(vehicle: str) -> list[tuple[str, float, int]]:
    store = ParamStore(vehicle_params(VEHICLE_TYPES[vehicle], 1, 255, False, [dict(DEFAULT_STREAM_RATES_HZ)], 1.0))
    return [(e.name, as_float(e.value), e.ptype) for e in store.entries()]


def _name(raw) -> str:
    return (raw.decode() if isinstance(raw, bytes) else raw).split("\0", 1)[0]


def read_param_pck(c, timeout: float = 10.0) -> bytes:
    """OpenFileRO @PARAM/param.pck, BurstReadFile from 0, ReadFile to fill gaps, as QGroundControl."""
    def request(opcode: int, data: bytes = b"", size: int = 0, offset: int = 0, seq: int = 0) -> int:
        mark = c.mark()
        payload = Payload(seq, 0, opcode, size or len(data), 0, 0, offset, data).pack()
        c.send(M.MAVLink_file_transfer_protocol_message(0, *VEHICLE, payload))
        return mark

    def replies(since: int):
        return [Payload.unpack(bytes(r.msg.payload)) for r in c.since(since, "FILE_TRANSFER_PROTOCOL") if r.src == VEHICLE]

    mark = request(Op.OPEN_FILE_RO, b"@PARAM/param.pck", seq=1)
    assert wait_for(c, is_type("FILE_TRANSFER_PROTOCOL", VEHICLE), timeout, since=mark) is not None
    [opened] = replies(mark)
    assert opened.opcode == Op.ACK, opened
    size = struct.unpack("<I", opened.data[:4])[0]
    mark = request(Op.BURST_READ_FILE, size=239, seq=2)
    chunks: dict[int, bytes] = {}
    quiet = 0
    for _ in range(int(timeout / 0.1)):
        before = len(chunks)
        pump([c], 0.1)
        for p in replies(mark):
            if p.opcode == Op.ACK and p.req_opcode in (Op.BURST_READ_FILE, Op.READ_FILE):
                chunks[p.offset] = p.data[:p.size]
        have = sum(len(v) for v in chunks.values())
        if have >= size:
            break
        quiet = quiet + 1 if len(chunks) == before else 0
        if quiet >= 5:  # half a second without a new block: read the first one missing
            offset = next((o for o in range(0, size, 239) if o not in chunks), have)
            mark = request(Op.READ_FILE, size=239, offset=offset, seq=3)
            quiet = 0
    data = b"".join(chunks[k] for k in sorted(chunks))
    assert len(data) == size, (len(data), size)
    return data


@pytest.mark.parametrize("vehicle", ["copter", "plane", "rover"])
def test_the_list_is_ardupilots_set_and_param_pck_serves_the_same(daemon, client, vehicle):
    d = daemon({"vehicle": {"type": vehicle}, "channels": [udp_channel("gcs")]})
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    mark = c.mark()
    got = download_params(c, timeout=20.0)
    listed = [(_name(got[i][0]), got[i][1], got[i][2]) for i in range(len(got))]
    want = expected(vehicle)
    assert [n for n, _, _ in listed] == [n for n, _, _ in want]
    assert [t for _, _, t in listed] == [t for _, _, t in want]
    assert [(n, v) for n, v, _ in listed if n not in COUNTED] == [(n, v) for n, v, _ in want if n not in COUNTED]
    assert {n: v for n, v, _ in listed}["STAT_BOOTCNT"] == 1  # a first start, as the SITL capture
    texts = [_name(r.msg.text) for r in c.since(mark, "STATUSTEXT") if r.src == VEHICLE]
    firmware = {"copter": "ArduCopter", "plane": "ArduPlane", "rover": "ArduRover"}[vehicle]
    assert f"{firmware} V4.6.3 (3fc7011a)" in texts  # the banner goes first, as ArduPilot's
    if vehicle == "copter":
        assert "Frame: QUAD/PLUS" in texts  # FRAME_CLASS 1, FRAME_TYPE 0: SITL's quad

    decoded = param_ftp.ftp_param_decode(read_param_pck(c))
    assert decoded is not None
    pck = [(n.decode(), as_float(v), PCK_TYPE[t]) for n, v, t in decoded.params]
    assert pck == listed


def test_autopilot_version_is_ardupilot_4_6_3_official_with_its_git_hash(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    mark = c.mark()
    c.command_long(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    r = wait_for(c, is_type("AUTOPILOT_VERSION", VEHICLE), since=mark)
    assert r is not None
    v = r.msg.flight_sw_version
    assert (v >> 24, (v >> 16) & 0xFF, (v >> 8) & 0xFF, v & 0xFF) == (4, 6, 3, M.FIRMWARE_VERSION_TYPE_OFFICIAL)
    assert bytes(r.msg.flight_custom_version) == b"3fc7011a"


def test_a_flight_mode_switch_on_rc_channels_override_changes_the_heartbeat_mode(daemon, client):
    """QGroundControl's Flight Modes page writes FLTMODE_CH / FLTMODE1..6; a joystick or MAVProxy's
    `rc 7 1900` then moves the switch: the HEARTBEAT's custom_mode follows after 200 ms."""
    d = daemon({"channels": [udp_channel("gcs")]})
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    for name, value in (("FLTMODE_CH", 7.0), ("FLTMODE6", 5.0)):  # channel 7, position 6: LOITER
        mark = c.mark()
        c.send(M.MAVLink_param_set_message(*VEHICLE, name.encode(), value, M.MAV_PARAM_TYPE_INT8))
        echo = wait_for(c, lambda r, n=name: r.type == "PARAM_VALUE" and _name(r.msg.param_id) == n, since=mark)
        assert echo is not None and echo.msg.param_value == value
    channels = [65535] * 18
    channels[6] = 1900
    mark = c.mark()
    sent = time.monotonic()
    c.send(M.MAVLink_rc_channels_override_message(*VEHICLE, *channels))
    loiter = wait_for(c, lambda r: is_type("HEARTBEAT", VEHICLE)(r) and r.msg.custom_mode == 5, 3.0, since=mark)
    assert loiter is not None
    assert loiter.t - sent >= 0.19  # not before the switch settled (200 ms)
