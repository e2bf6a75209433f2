"""Properties of the .plan reader over generated documents (hypothesis).

- Any JSON value, put in place of any part of QGC's example plan, either reads as a plan whose
  every item packs into a MISSION_ITEM_INT (no NaN, no infinity, nothing out of a field's range)
  or is refused with PlanError: nothing else escapes to the HTTP handler.
- Any valid geofence and rally points (the shapes QGroundControl makes, coordinates to 7
  decimals) read back unchanged after items -> .plan, and the vehicle's stores accept the items.
"""

import math

from hypothesis import example, given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as M
from tests.unit.test_http_plan_fence import HOME, normalised, qgc_plan

from gcsd.api.http.plan import PlanError, from_plan, to_plan
from gcsd.vehicle.mission.items import from_item_int, item_int_message
from gcsd.vehicle.mission.stores import FenceStore, RallyStore, validate

EDGES = [-1, 0, 1e-50, 255, 256, 65535, 65536, 2**31 - 1, 2**31, -(2**31) - 1, 2**64, 3.5e38, 1e39, 10**400]
NUMBER = (st.none() | st.booleans() | st.sampled_from(EDGES) | st.integers(-70_000, 70_000)
          | st.integers(-(10**400), 10**400) | st.floats(allow_nan=False))  # infinity included: JSON's 1e999
JSON = st.recursive(
    NUMBER | st.text(max_size=4),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)
PLACES = [  # (path into the plan, key to replace)
    (("geoFence",), "polygons"), (("geoFence",), "circles"), (("geoFence",), "breachReturn"),
    (("geoFence",), "version"), (("geoFence", "polygons", 0), "polygon"), (("geoFence", "polygons", 1), "inclusion"),
    (("geoFence", "polygons", 0, "polygon"), 2), (("geoFence", "polygons", 0, "polygon", 1), 0),
    (("geoFence", "circles", 0), "circle"), (("geoFence", "circles", 1, "circle"), "radius"),
    (("geoFence", "circles", 1, "circle"), "center"), (("geoFence", "circles", 0, "circle", "center"), 1),
    (("rallyPoints",), "points"), (("rallyPoints", "points"), 1), (("rallyPoints", "points", 0), 2),
    (("rallyPoints", "points", 2), 0), ((), "geoFence"), ((), "rallyPoints"),
    (("mission", "items", 1), "frame"), (("mission", "items", 1), "command"), (("mission", "items", 1, "params"), 6),
    (("mission", "items", 1, "params"), 0), (("mission", "items", 2, "params"), 4),
]
LAT = st.integers(-900_000_000, 900_000_000).map(lambda e7: e7 / 1e7)
LON = st.integers(-1_800_000_000, 1_800_000_000).map(lambda e7: e7 / 1e7)


def _wire(items, mission_type: int) -> tuple:
    """The items as a ground station downloads them: packed into MISSION_ITEM_INT and decoded."""
    mav = M.MAVLink(None, 1, 1)
    return tuple(from_item_int(mav.decode(bytearray(item_int_message(item, seq, mission_type, (255, 190)).pack(mav))))
                 for seq, item in enumerate(items))


RADIUS = (("geoFence", "circles", 1, "circle"), "radius")


@settings(max_examples=400, deadline=None)
@given(st.sampled_from(PLACES), NUMBER | JSON)
@example(RADIUS, 1e-50).via("a radius that is 0.0 as a float")
@example(RADIUS, 10**400).via("an integer too large for a float")
@example((("mission", "items", 1), "frame"), 256).via("a frame beyond uint8")
def test_any_value_anywhere_reads_as_a_plan_that_packs_or_is_refused(place, value):
    plan = qgc_plan()
    path, key = place
    part = plan
    for step in path:
        part = part[step]
    part[key] = value
    try:
        got = from_plan(plan)
    except PlanError:
        return
    _wire((HOME, *got.mission), M.MAV_MISSION_TYPE_MISSION)
    fence, rally = _wire(got.fence or (), M.MAV_MISSION_TYPE_FENCE), _wire(got.rally or (), M.MAV_MISSION_TYPE_RALLY)
    # what a ground station downloads is still a valid fence and rally (a radius of 1e-50 is 0.0 as a float)
    assert validate(FenceStore(10**6), fence) is None and validate(RallyStore(10**6), rally) is None
    for item in (*fence, *rally):
        assert all(math.isfinite(v) for v in (item.param1, item.param2, item.param3, item.param4, item.z))


POLYGON = st.builds(lambda inc, pts: {"version": 1, "inclusion": inc, "polygon": [[a, b] for a, b in pts]},
                    st.booleans(), st.lists(st.tuples(LAT, LON), min_size=3, max_size=12))
CIRCLE = st.builds(lambda inc, a, b, r: {"version": 1, "inclusion": inc, "circle": {"center": [a, b], "radius": r}},
                   st.booleans(), LAT, LON, st.floats(min_value=0.1, max_value=1e6))
POINT = st.tuples(LAT, LON, st.integers(-32768, 32767).map(float)).map(list)


@settings(max_examples=200, deadline=None)
@given(st.lists(POLYGON, max_size=4), st.lists(CIRCLE, max_size=4), st.none() | POINT, st.lists(POINT, max_size=8))
def test_any_valid_fence_and_rally_points_read_back_unchanged(polygons, circles, breach, points):
    plan = qgc_plan()
    plan["geoFence"] = {"version": 2, "polygons": polygons, "circles": circles}
    if breach is not None:
        plan["geoFence"]["breachReturn"] = breach
    plan["rallyPoints"] = {"version": 2, "points": points}
    got = from_plan(plan)
    assert validate(FenceStore(1000), got.fence) is None and validate(RallyStore(50), got.rally) is None
    again = to_plan((HOME, *got.mission), HOME, M.MAV_TYPE_QUADROTOR, got.fence, got.rally)
    assert normalised(again["geoFence"]) == normalised(plan["geoFence"])
    assert normalised(again["rallyPoints"]) == normalised(plan["rallyPoints"])
