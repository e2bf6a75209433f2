"""The mission, fence and rally stores: what each accepts, item by item and as a whole."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission import FenceStore, MissionItem, MissionStore, RallyStore
from gcsd.vehicle.mission.stores import validate

HOME = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 0, 1, 0, 0, 0, 0,
                   -353632620, 1491652370, 584.0)
LAT, LON = -353600000, 1491600000
ACCEPTED = M.MAV_MISSION_ACCEPTED
INC, EXC = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
CIRCLE_INC, CIRCLE_EXC = M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION
RETURN = M.MAV_CMD_NAV_FENCE_RETURN_POINT


def wp(seq: int = 1, **kw) -> MissionItem:
    item = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, x=LAT + seq, y=LON, z=20)
    return replace(item, **kw)


def jump(target: float) -> MissionItem:
    return MissionItem(M.MAV_CMD_DO_JUMP, M.MAV_FRAME_MISSION, param1=target, param2=2)


def vertex(command: int, n: float, i: int = 0) -> MissionItem:
    return MissionItem(command, M.MAV_FRAME_GLOBAL_INT, param1=n, x=LAT + 1000 * i, y=LON + 1000 * (i % 2))


def circle(command: int = CIRCLE_INC, radius: float = 100.0) -> MissionItem:
    return MissionItem(command, M.MAV_FRAME_GLOBAL_INT, param1=radius, x=LAT, y=LON)


def polygon(command: int, n: int, declared: float | None = None) -> list[MissionItem]:
    return [vertex(command, n if declared is None else declared, i) for i in range(n)]


def rally(**kw) -> MissionItem:
    item = MissionItem(M.MAV_CMD_NAV_RALLY_POINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, x=LAT, y=LON, z=50.0)
    return replace(item, **kw)


def mission_store(**kw) -> MissionStore:
    return MissionStore(700, lambda: HOME, **kw)


# --- mission ---------------------------------------------------------------------------------------


def test_mission_is_empty_until_home_is_set_and_then_holds_home_alone():
    store = mission_store()
    assert store.count() == 0
    assert store.item(0) == HOME  # readable all the same
    store.home_changed()
    assert store.count() == 1 and store.items() == (HOME,)


def test_mission_item_0_is_always_the_current_home():
    home = [HOME]
    store = MissionStore(700, lambda: home[0])
    store.replace((wp(0), wp(1)))
    home[0] = replace(HOME, x=HOME.x + 500)
    assert store.item(0) == home[0]
    assert store.item(1) == wp(1)


def test_mission_clear_then_home_change_gives_count_1():
    store = mission_store()
    store.replace((wp(0), wp(1)))
    store.replace(())
    assert store.count() == 0
    store.home_changed()
    assert store.count() == 1


@pytest.mark.parametrize(("item", "plan_count", "result"), [
    (wp(), 3, ACCEPTED),
    (wp(frame=M.MAV_FRAME_GLOBAL_TERRAIN_ALT), 3, ACCEPTED),
    (wp(frame=M.MAV_FRAME_LOCAL_NED), 3, M.MAV_MISSION_UNSUPPORTED_FRAME),
    (wp(frame=M.MAV_FRAME_BODY_FRD), 3, M.MAV_MISSION_UNSUPPORTED_FRAME),
    (wp(x=900_000_001), 3, M.MAV_MISSION_INVALID_PARAM5_X),
    (wp(y=1_800_000_001), 3, M.MAV_MISSION_INVALID_PARAM6_Y),
    (MissionItem(31999), 3, M.MAV_MISSION_UNSUPPORTED),
    # no location: any frame
    (MissionItem(M.MAV_CMD_DO_CHANGE_SPEED, M.MAV_FRAME_BODY_FRD, param2=5), 3, ACCEPTED),
    (jump(1), 3, ACCEPTED),
    (jump(2), 3, ACCEPTED),
    (jump(0), 3, M.MAV_MISSION_ERROR),  # home is not a jump target
    (jump(3), 3, M.MAV_MISSION_ERROR),  # beyond the plan
    (jump(-1), 3, M.MAV_MISSION_ERROR),
    (jump(math.nan), 3, M.MAV_MISSION_INVALID_PARAM1),  # ArduPilot's sanity_check_params comes first
    # NaN and infinity (ArduPilot's sanity_check_params; z: its location check, and never stored)
    (MissionItem(M.MAV_CMD_NAV_LOITER_TURNS, x=LAT, y=LON, z=20, param1=2, param3=math.nan), 3,
     M.MAV_MISSION_INVALID_PARAM3),
    (MissionItem(M.MAV_CMD_NAV_LOITER_TURNS, x=LAT, y=LON, z=20, param1=math.inf), 3,
     M.MAV_MISSION_INVALID_PARAM1),
    (wp(param2=-math.inf), 3, M.MAV_MISSION_INVALID_PARAM2),
    (wp(param4=math.nan), 3, ACCEPTED),  # a waypoint's yaw: NaN is "keep the heading mode"
    (wp(param4=math.inf), 3, M.MAV_MISSION_INVALID_PARAM4),
    (MissionItem(M.MAV_CMD_NAV_VTOL_LAND, x=LAT, y=LON, param3=math.nan, param4=math.nan), 3, ACCEPTED),
    (MissionItem(M.MAV_CMD_DO_CHANGE_SPEED, param4=math.nan), 3, M.MAV_MISSION_INVALID_PARAM4),
    (wp(z=math.nan), 3, M.MAV_MISSION_INVALID_PARAM7),
    (wp(z=83_000.0), 3, M.MAV_MISSION_INVALID_PARAM7),
    (wp(z=-82_999.0), 3, ACCEPTED),
    (MissionItem(M.MAV_CMD_DO_CHANGE_SPEED, param2=5, z=math.inf), 3, M.MAV_MISSION_INVALID_PARAM7),
    (replace(MissionItem(31999), param1=math.nan), 3, M.MAV_MISSION_INVALID_PARAM1),
])
def test_mission_item_checks(item, plan_count, result):
    assert mission_store().check_item(item, 1, plan_count) == result


def test_mission_item_0_is_not_checked_because_it_is_replaced_by_home():
    assert mission_store().check_item(MissionItem(31999), 0, 3) == ACCEPTED


def test_set_current_accepts_only_items_of_the_plan():
    store = mission_store()
    store.replace((wp(0), wp(1), wp(2)))
    assert store.set_current(2) and store.current_seq == 2
    assert not store.set_current(3) and store.current_seq == 2
    assert not store.set_current(-1)


def test_a_shorter_plan_resets_a_current_item_beyond_it():
    store = mission_store()
    store.replace((wp(0), wp(1), wp(2)))
    store.set_current(2)
    store.replace((wp(0), wp(1)))
    assert store.current_seq == 0


# --- fence -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(("item", "result"), [
    (vertex(INC, 4), ACCEPTED),
    (circle(CIRCLE_EXC), ACCEPTED),
    (MissionItem(RETURN, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, x=LAT, y=LON), ACCEPTED),
    (wp(), M.MAV_MISSION_UNSUPPORTED),
    # the home-centred circle of development.xml: not one of ArduPilot's
    (MissionItem(5005, M.MAV_FRAME_GLOBAL_INT, param1=100), M.MAV_MISSION_UNSUPPORTED),
    (replace(circle(), frame=M.MAV_FRAME_LOCAL_NED), M.MAV_MISSION_UNSUPPORTED_FRAME),
    (replace(circle(), frame=M.MAV_FRAME_MISSION), M.MAV_MISSION_UNSUPPORTED_FRAME),
    (vertex(EXC, 256), M.MAV_MISSION_INVALID_PARAM1),
    (vertex(EXC, 255), ACCEPTED),
    (vertex(EXC, math.nan), M.MAV_MISSION_INVALID_PARAM1),
    (circle(radius=math.inf), M.MAV_MISSION_INVALID_PARAM1),
    (circle(radius=math.nan), M.MAV_MISSION_INVALID_PARAM1),
    (replace(circle(), z=math.nan), M.MAV_MISSION_INVALID_PARAM7),
])
def test_fence_item_checks(item, result):
    assert FenceStore(100).check_item(item, 0, 1) == result


FENCE_PLANS = [
    ("empty", [], None),
    ("inclusion square", polygon(INC, 4), None),
    ("two polygons and circles",
     polygon(INC, 3) + [circle()] + polygon(EXC, 5) + [circle(CIRCLE_EXC, 10)], None),
    ("a return point", [MissionItem(RETURN, M.MAV_FRAME_GLOBAL_INT, x=LAT, y=LON)] + polygon(INC, 3), None),
    ("two vertices", polygon(INC, 2), "Fence: polygon at item 0 declares 2 vertices (needs at least 3)"),
    ("fewer vertices than declared", polygon(INC, 3, declared=4),
     "Fence: polygon at item 0 declares 4 vertices but has 3"),
    ("interrupted polygon", polygon(INC, 2, declared=4) + [circle()] + polygon(INC, 2, declared=4),
     "Fence: polygon at item 0 declares 4 vertices but has 2"),
    ("mixed vertex types", polygon(INC, 2, declared=3) + [vertex(EXC, 3)],
     "Fence: polygon at item 0 declares 3 vertices but has 2"),
    ("vertex count changes", polygon(INC, 2, declared=3) + [vertex(INC, 4)],
     "Fence: polygon at item 0 declares 3 vertices but has 2"),
    ("fractional count", polygon(INC, 3, declared=3.5),
     "Fence: polygon at item 0 declares 3.5 vertices (needs at least 3)"),
    ("zero radius", [circle(radius=0.0)], "Fence: circle at item 0 needs a radius > 0"),
    ("negative radius", polygon(INC, 3) + [circle(CIRCLE_EXC, -1.0)],
     "Fence: circle at item 3 needs a radius > 0"),
    ("NaN radius", [circle(radius=math.nan)], "Fence: circle at item 0 needs a radius > 0"),
    ("two return points", [MissionItem(RETURN, M.MAV_FRAME_GLOBAL_INT, x=LAT, y=LON)] * 2,
     "Fence: second return point at item 1 (at most one)"),
    ("bad vertex latitude", polygon(INC, 2, declared=3) + [replace(vertex(INC, 3, 2), x=950_000_000)],
     "Fence: item 2 has an invalid location"),
    ("bad circle longitude", [replace(circle(), y=-1_900_000_000)], "Fence: item 0 has an invalid location"),
]


@pytest.mark.parametrize(("plan", "reason"), [pytest.param(p, r, id=name) for name, p, r in FENCE_PLANS])
def test_fence_is_validated_as_a_whole(plan, reason):
    assert FenceStore(100).check_plan(tuple(plan)) == reason


def test_fence_polygon_vertex_with_a_bad_location_is_refused():
    plan = polygon(INC, 3)
    plan[1] = replace(plan[1], x=-910_000_000)
    assert FenceStore(100).check_plan(tuple(plan)) == "Fence: item 1 has an invalid location"


# --- rally -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(("item", "result"), [
    (rally(), ACCEPTED),
    (rally(frame=M.MAV_FRAME_GLOBAL), ACCEPTED),
    (rally(frame=M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT), ACCEPTED),
    (rally(command=M.MAV_CMD_NAV_WAYPOINT), M.MAV_MISSION_UNSUPPORTED),
    (rally(frame=M.MAV_FRAME_LOCAL_NED), M.MAV_MISSION_UNSUPPORTED_FRAME),
    (rally(x=900_000_001), M.MAV_MISSION_INVALID_PARAM5_X),
    (rally(x=-900_000_001), M.MAV_MISSION_INVALID_PARAM5_X),
    (rally(y=1_800_000_001), M.MAV_MISSION_INVALID_PARAM6_Y),
    (rally(z=32767.0), ACCEPTED),
    (rally(z=32768.0), M.MAV_MISSION_INVALID_PARAM7),
    (rally(z=-32769.0), M.MAV_MISSION_INVALID_PARAM7),
    (rally(z=math.inf), M.MAV_MISSION_INVALID_PARAM7),
    (rally(param1=math.nan), M.MAV_MISSION_INVALID_PARAM1),
])
def test_rally_item_checks(item, result):
    assert RallyStore(50).check_item(item, 0, 1) == result


# --- common ----------------------------------------------------------------------------------------


def test_replace_saves_before_adopting_and_a_failed_save_changes_nothing():
    saved = []
    store = RallyStore(50, save=saved.append)
    store.replace((rally(),))
    assert saved == [(rally(),)]

    def failing(items):
        raise OSError(30, "Read-only file system")

    store.save = failing
    with pytest.raises(OSError):
        store.replace((rally(), rally(z=10.0)))
    assert store.items() == (rally(),)


def test_mission_save_writes_home_as_item_0():
    saved = []
    store = MissionStore(700, lambda: HOME, save=saved.append)
    store.replace((wp(0, current=1), wp(1)))
    assert saved == [(replace(HOME, current=1), wp(1))]


@pytest.mark.parametrize(("store", "plan", "reason"), [
    (RallyStore(2), [rally()] * 3, "3 items, but only 2 are supported"),
    (RallyStore(50), [rally(), rally(y=1_800_000_001)], "item 1: MAV_MISSION_INVALID_PARAM6_Y"),
    (FenceStore(100), polygon(INC, 2), "Fence: polygon at item 0 declares 2 vertices (needs at least 3)"),
    (mission_store(), [HOME, wp(1), jump(5)], "item 2: MAV_MISSION_ERROR"),
    (mission_store(), [HOME, wp(1), jump(1)], None),
    (mission_store(), [HOME, wp(1, command=M.MAV_CMD_NAV_LOITER_TURNS, param3=math.nan)],
     "item 1: MAV_MISSION_INVALID_PARAM3"),
    (FenceStore(100), [circle(radius=math.inf)], "item 0: MAV_MISSION_INVALID_PARAM1"),
])
def test_a_loaded_plan_gets_every_check_an_upload_would(store, plan, reason):
    assert validate(store, tuple(plan)) == reason
    before = store.items()
    assert store.load(tuple(plan)) == reason
    assert store.items() == (before if reason else tuple(plan))
