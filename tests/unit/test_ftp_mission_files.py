"""`@MISSION/mission.dat|fence.dat|rally.dat` (REFERENCE.md 7.5): the byte format (golden bytes,
and pymavlink's MISSION_ITEM_INT unpacker as MAVProxy's `wp ftp` uses it as the oracle), reads
of a snapshot, uploads that go through the mission service's whole-plan checks."""

from __future__ import annotations

import errno
import struct

import pytest
from ftp_helpers import Gcs, errno_of, is_ack, nak_code
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.ftp.fs import ConfinedFs
from gcsd.vehicle.ftp.mission_files import MissionFiles, decode_plan, encode_plan
from gcsd.vehicle.ftp.protocol import Nak, Op
from gcsd.vehicle.ftp.server import FtpServer
from gcsd.vehicle.ftp.virtual import VirtualFiles
from gcsd.vehicle.mission.items import MissionItem

MISSION, FENCE, RALLY = M.MAV_MISSION_TYPE_MISSION, M.MAV_MISSION_TYPE_FENCE, M.MAV_MISSION_TYPE_RALLY

HOME = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 0, 1, 0, 0, 0, 0,
                   -353632620, 1491652370, 584.0)
WP = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 1, 1, 2.5, 0, 0, 90.0,
                 -353600000, 1491600000, 30.0)
TAKEOFF = MissionItem(M.MAV_CMD_NAV_TAKEOFF, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0, 1, 0, 0, 0, 0,
                      0, 0, 10.0)


class FakePlans:
    """The mission service's whole-plan interface, recording writes."""

    def __init__(self, result: int = M.MAV_MISSION_ACCEPTED) -> None:
        self.plans = {MISSION: (HOME, TAKEOFF, WP), FENCE: (), RALLY: ()}
        self.result = result
        self.written: list[tuple[int, list[MissionItem]]] = []

    def read_plan(self, mission_type: int):
        return self.plans.get(mission_type)

    def write_plan(self, mission_type: int, items) -> int:
        self.written.append((mission_type, list(items)))
        if self.result == M.MAV_MISSION_ACCEPTED:
            self.plans[mission_type] = tuple(items)
        return self.result


@pytest.fixture
def plans():
    return FakePlans()


@pytest.fixture
def gcs(tmp_path, plans):
    return Gcs(FtpServer(ConfinedFs(tmp_path / "root", 1 << 20), VirtualFiles(None, MissionFiles(plans))))


def test_golden_bytes_header_then_mission_item_int_payloads_in_wire_order():
    data = encode_plan(MISSION, [HOME, WP])
    assert data[:10] == struct.pack("<HHHHH", 0x763D, MISSION, 0, 0, 2)
    assert len(data) == 10 + 2 * 38
    assert data[48:] == struct.pack("<ffffiifHHBBBBBB", 2.5, 0, 0, 90.0, -353600000, 1491600000, 30.0,
                                    1, M.MAV_CMD_NAV_WAYPOINT, 0, 0, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                    1, 1, MISSION)


def test_pymavlink_unpacks_the_items_as_mavproxy_does():
    data = encode_plan(MISSION, [HOME, TAKEOFF, WP])
    msg_class = M.MAVLink_mission_item_int_message
    got = []
    for i in range(3):
        fields = msg_class.unpacker.unpack(data[10 + 38 * i:10 + 38 * (i + 1)])
        msg = msg_class(*[fields[msg_class.orders[k]] for k in range(len(fields))])
        got.append((msg.seq, msg.command, msg.frame, msg.x, msg.y, msg.z, msg.param1, msg.param4,
                    msg.current))
    assert got == [
        (0, HOME.command, HOME.frame, HOME.x, HOME.y, HOME.z, 0, 0, 0),
        (1, TAKEOFF.command, TAKEOFF.frame, 0, 0, 10.0, 0, 0, 0),
        (2, WP.command, WP.frame, WP.x, WP.y, 30.0, 2.5, 90.0, 1),
    ]


def test_decode_reads_back_what_encode_wrote():
    assert decode_plan(encode_plan(FENCE, [WP, TAKEOFF]), FENCE) == [WP, TAKEOFF]


@pytest.mark.parametrize("mangle", [
    lambda d: struct.pack("<H", 0x671B) + d[2:],  # magic
    lambda d: d[:2] + struct.pack("<H", RALLY) + d[4:],  # another plan's type
    lambda d: d[:8] + struct.pack("<H", 3) + d[10:],  # count is not the length
    lambda d: d[:4] + struct.pack("<H", 1) + d[6:],  # options (partial update)
    lambda d: d[:6] + struct.pack("<H", 1) + d[8:],  # start (partial update)
    lambda d: d[:10] + bytes(38) + d[48:],  # an item left all zero
])
def test_malformed_files_are_refused(mangle):
    assert decode_plan(mangle(encode_plan(MISSION, [HOME, WP])), MISSION) is None


def test_reading_mission_dat_gives_the_plan_with_its_exact_size(gcs, plans):
    reply = gcs.one(Op.OPEN_FILE_RO, b"@MISSION/mission.dat")
    expected = encode_plan(MISSION, plans.plans[MISSION])
    assert int.from_bytes(reply.data[:4], "little") == len(expected)
    assert gcs.download(block=80) == expected


def test_listing_at_mission_shows_the_three_files_with_their_sizes(gcs):
    listing = gcs.one(Op.LIST_DIRECTORY, b"/@MISSION/").data.split(b"\0")[:3]
    assert listing == [b"Fmission.dat\t124", b"Ffence.dat\t10", b"Frally.dat\t10"]


def test_the_root_listing_shows_at_mission(gcs):
    assert b"D@MISSION" in gcs.one(Op.LIST_DIRECTORY, b"/").data.split(b"\0")


def test_writing_fence_dat_replaces_the_plan_when_the_session_ends(gcs, plans):
    data = encode_plan(FENCE, [WP, TAKEOFF])
    assert is_ack(gcs.one(Op.CREATE_FILE, b"@MISSION/fence.dat"))
    for offset in range(0, len(data), 50):
        assert is_ack(gcs.one(Op.WRITE_FILE, data[offset:offset + 50], offset=offset))
    assert plans.written == []
    assert is_ack(gcs.one(Op.TERMINATE_SESSION))
    assert plans.written == [(FENCE, [WP, TAKEOFF])]


def test_a_plan_the_mission_service_refuses_is_einval_and_changes_nothing(tmp_path):
    refusing = FakePlans(result=M.MAV_MISSION_ERROR)
    gcs = Gcs(FtpServer(ConfinedFs(tmp_path / "root", 1 << 20), VirtualFiles(None, MissionFiles(refusing))))
    gcs.one(Op.CREATE_FILE, b"@MISSION/rally.dat")
    gcs.one(Op.WRITE_FILE, encode_plan(RALLY, [WP]))
    assert errno_of(gcs.one(Op.TERMINATE_SESSION)) == errno.EINVAL
    assert refusing.plans[RALLY] == ()


def test_a_malformed_upload_is_einval_and_never_reaches_the_service(gcs, plans):
    gcs.one(Op.CREATE_FILE, b"@MISSION/mission.dat")
    gcs.one(Op.WRITE_FILE, encode_plan(FENCE, [WP]))  # a fence file written as the mission
    assert errno_of(gcs.one(Op.TERMINATE_SESSION)) == errno.EINVAL
    assert plans.written == []


def test_one_upload_per_file_at_a_time(tmp_path, plans):
    server = FtpServer(ConfinedFs(tmp_path / "root", 1 << 20), VirtualFiles(None, MissionFiles(plans)))
    first, second = Gcs(server, sysid=200), Gcs(server, sysid=201)
    assert is_ack(first.one(Op.CREATE_FILE, b"@MISSION/mission.dat"))
    assert errno_of(second.one(Op.CREATE_FILE, b"@MISSION/mission.dat")) == errno.EBUSY
    assert is_ack(second.one(Op.CREATE_FILE, b"@MISSION/fence.dat"))


def test_an_abandoned_upload_changes_nothing(gcs, plans):
    gcs.one(Op.CREATE_FILE, b"@MISSION/mission.dat", now=0.0)
    gcs.one(Op.WRITE_FILE, encode_plan(MISSION, [HOME]), now=0.0)
    gcs.server.expire(100.0)
    assert plans.written == []
    assert is_ack(Gcs(gcs.server, sysid=9).one(Op.CREATE_FILE, b"@MISSION/mission.dat", now=100.0))


def test_unknown_mission_file_names_are_file_not_found(gcs):
    assert nak_code(gcs.one(Op.OPEN_FILE_RO, b"@MISSION/other.dat")) == Nak.FILE_NOT_FOUND
