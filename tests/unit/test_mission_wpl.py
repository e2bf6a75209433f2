"""Plan files (QGC WPL 110) and the item conversions between MISSION_ITEM and MISSION_ITEM_INT."""

from __future__ import annotations

import math
import struct
from textwrap import dedent

import pytest
from pymavlink import mavwp
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission import MissionItem
from gcsd.vehicle.mission.items import from_item_float, from_item_int, item_float_message, item_int_message
from gcsd.vehicle.mission.wpl import WplError, dumps, loads


def _roundtrip(value: float) -> float:
    """A value as a MAVLink float field carries it (float32)."""
    return struct.unpack("<f", struct.pack("<f", value))[0]


PLAN = [
    MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 1, 1, 0, 0, 0, 0, -353632620, 1491652370, 584.0),
    MissionItem(M.MAV_CMD_NAV_TAKEOFF, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0, 1, _roundtrip(15.0), 0, 0,
                _roundtrip(0.1), -353632619, 1491652371, _roundtrip(12.3456789)),
    MissionItem(M.MAV_CMD_DO_JUMP, M.MAV_FRAME_MISSION, 0, 1, 1.0, 3.0, 0, 0, 0, 0, 0.0),
    MissionItem(M.MAV_CMD_DO_SET_SERVO, M.MAV_FRAME_MISSION, 0, 0, 9.0, 1900.0, 0, 0, -7, 123456, 0.0),
    MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_LOCAL_NED, 0, 1, 0, 0, 0, math.nan, 123456, -98765, -5.5),
    MissionItem(M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_FRAME_GLOBAL_INT, 0, 1, 3.0, 0, 0, 0,
                -900000000, -1800000000, 0.0),
    MissionItem(M.MAV_CMD_NAV_RALLY_POINT, M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, 0, 0, 0, 0, 0, 0,
                5, -5, _roundtrip(1e-7)),
]


def _same(a: MissionItem, b: MissionItem) -> bool:
    fa, fb = (a.param1, a.param2, a.param3, a.param4, a.z), (b.param1, b.param2, b.param3, b.param4, b.z)
    floats_equal = all(x == y or (math.isnan(x) and math.isnan(y)) for x, y in zip(fa, fb))
    return floats_equal and (a.command, a.frame, a.current, a.autocontinue, a.x, a.y) == (
        b.command, b.frame, b.current, b.autocontinue, b.x, b.y)


def test_a_plan_round_trips_through_the_file_exactly():
    back = loads(dumps(PLAN))
    assert len(back) == len(PLAN)
    assert all(_same(a, b) for a, b in zip(back, PLAN)), (back, PLAN)


def test_the_file_is_qgc_wpl_110_with_seven_decimal_degrees():
    text = dumps(PLAN[:2])
    lines = text.splitlines()
    assert lines[0] == "QGC WPL 110"
    assert lines[1].split("\t") == [
        "0", "1", "0", "16", "0", "0", "0", "0", "-35.3632620", "149.1652370", "584", "1"]
    assert lines[2].split("\t")[8:10] == ["-35.3632619", "149.1652371"]


def test_pymavlink_mavwp_reads_our_files(tmp_path):
    path = tmp_path / "mission.waypoints"
    path.write_text(dumps(PLAN[:4]))
    loader = mavwp.MAVWPLoader()
    assert loader.load(str(path)) == 4
    first, second = loader.wp(0), loader.wp(1)
    assert (first.command, first.current, first.frame) == (16, 1, 0)
    assert (first.x, first.y, first.z) == (pytest.approx(-35.363262), pytest.approx(149.165237), 584.0)
    assert second.x == pytest.approx(-35.3632619, abs=1e-9) and second.param1 == 15.0


def test_mavproxy_style_files_with_six_decimals_are_read():
    text = dedent("""\
        QGC WPL 110
        0\t1\t0\t16\t0.000000\t0.000000\t0.000000\t0.000000\t-35.363262\t149.165237\t584.000000\t1
        # a comment MAVProxy keeps
        1\t0\t3\t22\t0.000000\t0.000000\t0.000000\t0.000000\t0.000000\t0.000000\t20.000000\t1

        2\t0\t0\t177\t1.000000\t2.000000\t0.000000\t0.000000\t0.000000\t0.000000\t0.000000\t1
        """)
    items = loads(text)
    assert [i.command for i in items] == [16, 22, 177]
    assert (items[0].x, items[0].y) == (-353632620, 1491652370)
    assert (items[2].param1, items[2].param2) == (1.0, 2.0)


def test_an_empty_plan_is_just_the_header():
    assert dumps([]) == "QGC WPL 110\n"
    assert loads("QGC WPL 110\n") == []


@pytest.mark.parametrize(("text", "line", "reason"), [
    ("", 1, "expected the header 'QGC WPL 110', got 'an empty file'"),
    ("QGC WPL 100\n", 1, "expected the header 'QGC WPL 110', got 'QGC WPL 100'"),
    ("QGC WPL 110\n0\t1\t0\t16\t0\t0\n", 2, "expected 12 values, got 6"),
    ("QGC WPL 110\n1\t0\t0\t16\t0\t0\t0\t0\t1\t2\t3\t1\n", 2, "expected seq 0, got 1"),
    ("QGC WPL 110\n0\t0\t0\t16\t0\t0\t0\t0\tnorth\t2\t3\t1\n", 2,
     "could not convert string to float: 'north'"),
    ("QGC WPL 110\n0\t0\t0\t16\t0\t0\t0\t0\tnan\t2\t3\t1\n", 2, "x or y is not a finite number"),
    ("QGC WPL 110\n0\t0\t0\t177\t0\t0\t0\t0\t1e12\t2\t3\t1\n", 2, "x or y out of range"),
])
def test_a_bad_file_is_reported_with_its_line(text, line, reason):
    with pytest.raises(WplError) as caught:
        loads(text)
    assert (caught.value.line, caught.value.reason) == (line, reason)


# --- conversions ---------------------------------------------------------------------------------


def _float_item(command, frame, x, y, **kw):
    return M.MAVLink_mission_item_message(1, 1, 0, frame, command, 0, 1, kw.get("p1", 0.0), 0, 0, 0, x, y,
                                          kw.get("z", 10.0), 0)


@pytest.mark.parametrize(("frame", "x", "y", "xi", "yi"), [
    (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, -35.3632619, 149.1652371, -353632619, 1491652371),
    (M.MAV_FRAME_GLOBAL, 0.00000005, -0.00000005, 0, 0),  # rounded to the nearest degE7
    (M.MAV_FRAME_LOCAL_NED, 12.5, -3.25, 125000, -32500),  # metres x 1e4
])
def test_legacy_item_locations_are_scaled_by_frame(frame, x, y, xi, yi):
    item = from_item_float(_float_item(M.MAV_CMD_NAV_WAYPOINT, frame, x, y))
    assert (item.x, item.y) == (xi, yi)
    back = item_float_message(item, 0, 0, (255, 190))
    assert back.x == pytest.approx(x, abs=1e-7) and back.y == pytest.approx(y, abs=1e-7)


def test_legacy_item_location_in_an_unsupported_frame_is_refused():
    assert from_item_float(_float_item(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_BODY_FRD, 1.0, 2.0)) == (
        M.MAV_MISSION_UNSUPPORTED_FRAME)


def test_legacy_item_without_a_location_keeps_x_and_y_as_integers():
    item = from_item_float(_float_item(M.MAV_CMD_DO_SET_SERVO, M.MAV_FRAME_BODY_FRD, 7.9, -3.2))
    assert (item.x, item.y) == (7, -3)
    assert item_float_message(item, 0, 0, (1, 1)).x == 7.0


@pytest.mark.parametrize(("x", "y", "result"), [
    (math.nan, 0.0, M.MAV_MISSION_INVALID_PARAM5_X),
    (0.0, math.inf, M.MAV_MISSION_INVALID_PARAM6_Y),
    (1e12, 0.0, M.MAV_MISSION_INVALID_PARAM5_X),
])
def test_legacy_item_with_unusable_x_or_y_is_refused(x, y, result):
    assert from_item_float(_float_item(M.MAV_CMD_DO_SET_SERVO, M.MAV_FRAME_MISSION, x, y)) == result


def test_item_int_round_trips_through_the_message():
    for seq, item in enumerate(PLAN):
        msg = item_int_message(item, seq, M.MAV_MISSION_TYPE_FENCE, (255, 190))
        decoded = M.MAVLink(None).decode(bytearray(msg.pack(M.MAVLink(None, 1, 1))))
        assert decoded.seq == seq and decoded.target_system == 255
        assert decoded.mission_type == M.MAV_MISSION_TYPE_FENCE
        assert _same(from_item_int(decoded), item)
