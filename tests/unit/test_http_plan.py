"""QGroundControl .plan v2 <-> mission items (gcsd.api.http.plan)."""

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.api.http.plan import PlanError, from_plan, to_plan
from gcsd.vehicle.mission.items import MissionItem

HOME = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 0, 1, 0, 0, 0, 0, -353632621, 1491652374, 584.0)
# as QGroundControl writes one (a takeoff, a waypoint with NaN yaw written as null, a speed change)
QGC_PLAN = {
    "fileType": "Plan", "groundStation": "QGroundControl", "version": 1,
    "geoFence": {"circles": [], "polygons": [], "version": 2},
    "rallyPoints": {"points": [], "version": 2},
    "mission": {
        "version": 2, "firmwareType": 3, "vehicleType": 2, "cruiseSpeed": 15, "hoverSpeed": 5,
        "globalPlanAltitudeMode": 1, "plannedHomePosition": [-35.3632621, 149.1652374, 584],
        "items": [
            {"type": "SimpleItem", "autoContinue": True, "command": 22, "doJumpId": 1, "frame": 3,
             "params": [0, 0, 0, None, -35.36, 149.16, 20], "AltitudeMode": 1, "Altitude": 20,
             "AMSLAltAboveTerrain": None},
            {"type": "SimpleItem", "autoContinue": True, "command": 16, "doJumpId": 2, "frame": 3,
             "params": [0, 0, 0, None, -35.3625, 149.1655, 30]},
            {"type": "SimpleItem", "autoContinue": True, "command": 178, "doJumpId": 3, "frame": 2,
             "params": [1, 8, -1, 0, 0, 0, 0]},
        ],
    },
}


def test_qgc_plan_becomes_items_with_degE7_and_nan():
    items = from_plan(QGC_PLAN).mission
    assert [i.command for i in items] == [22, 16, 178]
    assert (items[1].x, items[1].y, items[1].z) == (-353625000, 1491655000, 30.0)
    assert math.isnan(items[1].param4)
    assert (items[2].param1, items[2].param2, items[2].x) == (1.0, 8.0, 0)


def test_items_become_a_plan_that_reads_back_the_same():
    items = from_plan(QGC_PLAN).mission
    plan = to_plan((HOME, *items), HOME, M.MAV_TYPE_QUADROTOR)
    assert plan["mission"]["plannedHomePosition"] == [-35.3632621, 149.1652374, 584.0]
    assert [e["doJumpId"] for e in plan["mission"]["items"]] == [1, 2, 3]
    assert plan["mission"]["items"][1]["params"][3] is None  # NaN as QGC writes it
    again = from_plan(plan).mission
    assert [(i.command, i.frame, i.x, i.y, i.z) for i in again] == [(i.command, i.frame, i.x, i.y, i.z) for i in items]


@pytest.mark.parametrize("change,error", [
    (lambda p: p.update(fileType="Mission"), "fileType"),
    (lambda p: p["mission"].update(version=1), "version"),
    (lambda p: p["mission"]["items"][0].update(type="ComplexItem"), "only SimpleItem"),
    (lambda p: p["mission"]["items"][0].update(command="22"), "command"),
    (lambda p: p["mission"]["items"][0].update(params=[0, 0]), "7 numbers"),
    (lambda p: p["mission"]["items"][0]["params"].__setitem__(4, None), "x and y"),
    (lambda p: p["mission"]["items"][0]["params"].__setitem__(0, "a"), r"params\[0\]"),
    (lambda p: p["mission"]["items"][0].update(autoContinue=1), "autoContinue"),
    (lambda p: p["mission"]["items"][0]["params"].__setitem__(6, 1e39), "32-bit float"),
    (lambda p: p["mission"]["items"][0]["params"].__setitem__(0, float("inf")), "32-bit float"),
    (lambda p: p["mission"].update(items={}), "a list"),
])
def test_bad_plans_say_where(change, error):
    import copy
    plan = copy.deepcopy(QGC_PLAN)
    change(plan)
    with pytest.raises(PlanError, match=error):
        from_plan(plan)
