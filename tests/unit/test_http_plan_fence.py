""".plan geoFence and rallyPoints <-> fence and rally items (gcsd.api.http.planfence), on a QGC example.

tests/data/qgc/fence_rally.plan is written by hand in QGroundControl's format (GeoFenceController,
QGCFencePolygon, QGCFenceCircle, RallyPointController; keys sorted and indented as Qt writes them):
an inclusion polygon of 5 vertices, an exclusion polygon of 4, an inclusion and an exclusion
circle, a breach return point, 3 rally points.
"""

import json
import math
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.api.http.plan import PlanError, from_plan, to_plan
from gcsd.api.http.planfence import fence_json, rally_json
from gcsd.vehicle.mission.items import MissionItem
from gcsd.vehicle.mission.stores import FenceStore, RallyStore, validate

QGC_FILE = Path(__file__).resolve().parents[1] / "data" / "qgc" / "fence_rally.plan"
HOME = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 0, 1, 0, 0, 0, 0, -353632621, 1491652374, 584.0)
V_IN, V_OUT = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
C_IN, C_OUT = M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION


def qgc_plan() -> dict:
    return json.loads(QGC_FILE.read_text(encoding="utf-8"))


def normalised(part: object) -> object:
    """Coordinates to the 7 decimals degE7 keeps, ints and floats alike."""
    if isinstance(part, dict):
        return {k: normalised(v) for k, v in part.items()}
    if isinstance(part, list):
        return [normalised(v) for v in part]
    if isinstance(part, (int, float)) and not isinstance(part, bool):
        return round(float(part), 7)
    return part


def test_the_qgc_fence_becomes_the_items_qgc_uploads_to_ardupilot():
    fence = from_plan(qgc_plan()).fence
    assert [i.command for i in fence] == [V_IN] * 5 + [V_OUT] * 4 + [C_IN, C_OUT, M.MAV_CMD_NAV_FENCE_RETURN_POINT]
    assert [i.param1 for i in fence[:9]] == [5.0] * 5 + [4.0] * 4  # the vertex count in each vertex
    assert (fence[0].x, fence[0].y) == (-353598725, 1491613213)  # degE7, as MISSION_ITEM_INT
    assert (fence[9].param1, fence[9].x, fence[9].y) == (750.0, -353632621, 1491652374)
    assert fence[10].param1 == 42.5
    assert {i.frame for i in fence[:11]} == {M.MAV_FRAME_GLOBAL} and {i.autocontinue for i in fence} == {0}
    ret = fence[11]
    assert (ret.frame, ret.x, ret.y, ret.z) == (M.MAV_FRAME_GLOBAL_RELATIVE_ALT, -353628000, 1491651000, 30.0)
    assert validate(FenceStore(100), fence) is None  # everything the vehicle's store checks


def test_the_qgc_rally_points_become_rally_items():
    rally = from_plan(qgc_plan()).rally
    assert [(i.command, i.frame) for i in rally] == [(M.MAV_CMD_NAV_RALLY_POINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT)] * 3
    assert [(i.x, i.y, i.z) for i in rally] == [(-353603566, 1491625118, 25.0), (-353662018, 1491689844, 30.5),
                                               (-353625874, 1491601237, -12.0)]
    assert validate(RallyStore(50), rally) is None


def test_the_items_read_back_as_the_same_geofence_and_rally_points():
    document = qgc_plan()
    plan = from_plan(document)
    again = to_plan((HOME, *plan.mission), HOME, M.MAV_TYPE_QUADROTOR, plan.fence, plan.rally)
    assert normalised(again["geoFence"]) == normalised(document["geoFence"])
    assert normalised(again["rallyPoints"]) == normalised(document["rallyPoints"])
    assert from_plan(again) == plan


def test_a_fence_a_ground_station_uploaded_in_another_order_is_grouped_into_its_shapes():
    tri = [MissionItem(V_OUT, M.MAV_FRAME_GLOBAL_INT, 0, 1, 3.0, x=10 + n, y=20) for n in range(3)]
    circle = MissionItem(C_IN, M.MAV_FRAME_GLOBAL_INT, 0, 1, 100.0, x=5, y=6)
    fence = (circle, *tri, circle)
    assert validate(FenceStore(100), fence) is None
    got = fence_json(fence)
    assert [p["inclusion"] for p in got["polygons"]] == [False]
    assert got["polygons"][0]["polygon"] == [[1e-6, 2e-6], [1.1e-6, 2e-6], [1.2e-6, 2e-6]]
    assert len(got["circles"]) == 2 and "breachReturn" not in got
    assert fence_json(()) == {"version": 2, "polygons": [], "circles": []}
    assert rally_json(()) == {"version": 2, "points": []}


def test_a_plan_without_geofence_or_rally_points_leaves_them_out():
    document = qgc_plan()
    del document["geoFence"], document["rallyPoints"]
    plan = from_plan(document)
    assert (plan.fence, plan.rally) == (None, None) and len(plan.mission) == 4


def _polygon(p, n):
    return p["geoFence"]["polygons"][n]


def _circle(p, n):
    return p["geoFence"]["circles"][n]["circle"]


BAD = [
    # polygons
    (lambda p: _polygon(p, 0).update(polygon=_polygon(p, 0)["polygon"][:2]), r"polygons\[0\].polygon: 2 vertices"),
    (lambda p: _polygon(p, 1).update(polygon=[[-35.0, 149.0]] * 256), r"polygons\[1\].polygon: 256 vertices"),
    (lambda p: _polygon(p, 0)["polygon"].__setitem__(2, [None, 149.0]), r"polygon\[2\]: None .*null is NaN"),
    (lambda p: _polygon(p, 0)["polygon"].__setitem__(1, [90.5, 149.0]), r"polygon\[1\]: latitude 90.5"),
    (lambda p: _polygon(p, 0)["polygon"].__setitem__(1, [-35.0, -180.1]), r"polygon\[1\]: longitude -180.1"),
    (lambda p: _polygon(p, 0)["polygon"].__setitem__(1, [-35.0, math.inf]), r"polygon\[1\]: inf"),
    (lambda p: _polygon(p, 0)["polygon"].__setitem__(1, [-35.0, 149.0, 10]), r"polygon\[1\]: expected \[lat, lon\]"),
    (lambda p: _polygon(p, 0)["polygon"].__setitem__(1, [True, 149.0]), r"polygon\[1\]: True"),
    (lambda p: _polygon(p, 0)["polygon"].__setitem__(1, ["-35", 149.0]), r"polygon\[1\]: '-35'"),
    (lambda p: _polygon(p, 0).update(polygon={}), r"polygons\[0\].polygon: expected a list"),
    (lambda p: _polygon(p, 0).pop("inclusion"), r"polygons\[0\].inclusion: expected true or false"),
    (lambda p: _polygon(p, 0).update(inclusion=1), r"polygons\[0\].inclusion"),
    (lambda p: _polygon(p, 0).update(version=2), r"polygons\[0\].version: 2"),
    (lambda p: p["geoFence"]["polygons"].append([]), r"polygons\[2\]: expected an object"),
    # circles
    (lambda p: _circle(p, 0).update(radius=0), r"circles\[0\].circle.radius: 0"),
    (lambda p: _circle(p, 1).update(radius=-5.0), r"circles\[1\].circle.radius: -5.0"),
    (lambda p: _circle(p, 1).update(radius=None), r"circles\[1\].circle.radius: None"),
    (lambda p: _circle(p, 1).update(radius=math.inf), r"circles\[1\].circle.radius: inf"),
    (lambda p: _circle(p, 1).update(radius=1e39), r"circles\[1\].circle.radius"),
    (lambda p: _circle(p, 1).update(radius=1e-50), r"circles\[1\].circle.radius: 1e-50"),  # 0.0 as a float
    (lambda p: _circle(p, 1).update(radius=10**400), r"circles\[1\].circle.radius: 1000"),
    (lambda p: _circle(p, 0).update(center=[-91.0, 149.0]), r"circles\[0\].circle.center: latitude -91"),
    (lambda p: _circle(p, 0).pop("center"), r"circles\[0\].circle.center: expected \[lat, lon\]"),
    (lambda p: p["geoFence"]["circles"][0].pop("circle"), r"circles\[0\].circle: expected"),
    # the fence as a whole
    (lambda p: p["geoFence"].update(version=1), r"geoFence.version: 1, only version 2"),
    (lambda p: p["geoFence"].pop("polygons"), r"geoFence.polygons: expected a list"),
    (lambda p: p["geoFence"].update(circles=None), r"geoFence.circles: expected a list"),
    (lambda p: p.update(geoFence=[]), r"geoFence: expected an object"),
    (lambda p: p["geoFence"].update(breachReturn=[-35.36, 149.16]), r"breachReturn: expected \[lat, lon, alt\]"),
    (lambda p: p["geoFence"].update(breachReturn=[-35.36, 149.16, None]), r"breachReturn: None"),
    (lambda p: p["geoFence"].update(breachReturn=[-35.36, 149.16, 1e6]), r"breachReturn: altitude 1e\+06"),
    # rally points
    (lambda p: p["rallyPoints"]["points"].__setitem__(1, [-35.36, 149.16]), r"points\[1\]: expected \[lat, lon, alt\]"),
    (lambda p: p["rallyPoints"]["points"].__setitem__(2, [-35.36, 181, 10]), r"points\[2\]: longitude 181"),
    (lambda p: p["rallyPoints"]["points"].__setitem__(0, [None, 149.16, 10]), r"points\[0\]: None"),
    (lambda p: p["rallyPoints"]["points"].__setitem__(0, [-35.36, 149.16, 40000]), r"points\[0\]: altitude 40000"),
    (lambda p: p["rallyPoints"].update(version=1), r"rallyPoints.version: 1"),
    (lambda p: p["rallyPoints"].update(points="x"), r"rallyPoints.points: expected a list"),
]


@pytest.mark.parametrize("change,error", BAD)
def test_bad_fences_and_rally_points_are_refused_saying_where(change, error):
    plan = qgc_plan()
    from_plan(plan)  # positive control: the plan as QGC wrote it is taken
    change(plan)
    with pytest.raises(PlanError, match=error):
        from_plan(plan)


def test_the_limits_of_a_polygon_are_taken():
    plan = qgc_plan()
    _polygon(plan, 0)["polygon"] = _polygon(plan, 0)["polygon"][:3]
    _polygon(plan, 1)["polygon"] = [[-35.0 + n * 1e-4, 149.0] for n in range(255)]
    _circle(plan, 0)["radius"] = 0.01
    fence = from_plan(plan).fence
    assert [i.param1 for i in fence[:3]] == [3.0] * 3 and fence[3].param1 == 255.0
    assert validate(FenceStore(300), fence) is None
