"""A `.plan`'s geoFence and rallyPoints to and from fence and rally items, as QGroundControl does.

The JSON (QGC's GeoFenceController, QGCFencePolygon, QGCFenceCircle, RallyPointController, all
read, none copied):
  "geoFence": {"version": 2, "polygons": [{"version": 1, "inclusion": true,
               "polygon": [[lat, lon], ...]}], "circles": [{"version": 1, "inclusion": false,
               "circle": {"center": [lat, lon], "radius": metres}}], "breachReturn": [lat, lon, alt]}
  "rallyPoints": {"version": 2, "points": [[lat, lon, alt], ...]}
breachReturn is optional. A coordinate is exactly [lat, lon] (fence) or [lat, lon, alt] (rally,
breachReturn), as QGC's JsonHelper demands; QGC writes NaN as null, which no fence or rally
point can hold, so null is refused here.

The items, as QGC's GeoFenceManager and RallyPointManager upload them to ArduPilot: each polygon
vertex a NAV_FENCE_POLYGON_VERTEX_INCLUSION / _EXCLUSION with the polygon's vertex count in
param1, every polygon before the circles; a circle NAV_FENCE_CIRCLE_INCLUSION / _EXCLUSION with
its radius in param1; the breach return point last, NAV_FENCE_RETURN_POINT; all in
MAV_FRAME_GLOBAL (the return point GLOBAL_RELATIVE_ALT, with its altitude in z), autocontinue 0,
latitude and longitude as degE7. Rally points NAV_RALLY_POINT in GLOBAL_RELATIVE_ALT, z the altitude.

Reading is strict and says where (`PlanError`, 422): a missing or mistyped key, a version other
than QGC's, a coordinate that is not finite numbers within +-90 / +-180, an altitude beyond
ArduPilot's (+-83 km; rally points an int16 of metres), a polygon of fewer than 3 or more than
255 vertices, a radius not > 0 as a 32-bit float (nor beyond one). Writing groups a fence
back into polygons (consecutive vertices of one command, param1 of them), circles and the return
point, whatever order a ground station uploaded them in.
"""

from __future__ import annotations

import struct

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission.items import LOCATION_ALT_MAX_M, MissionItem
from gcsd.vehicle.mission.stores import (
    CIRCLE_COMMANDS,
    INT16_MAX,
    INT16_MIN,
    MAX_POLYGON_VERTICES,
    MIN_POLYGON_VERTICES,
    VERTEX_COMMANDS,
)

FLOAT32_MAX = 3.4028234663852886e38  # a MISSION_ITEM_INT param: a larger value would go out as inf
FENCE_VERSION, SHAPE_VERSION, RALLY_VERSION = 2, 1, 2
VERTEX = {True: M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, False: M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION}
CIRCLE = {True: M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, False: M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION}
FENCE_FRAME = M.MAV_FRAME_GLOBAL
POINT_FRAME = M.MAV_FRAME_GLOBAL_RELATIVE_ALT  # rally points and the breach return point


class PlanError(ValueError):
    """The document is not a .plan gcsd can take (422); the text says where."""


# --- reading -------------------------------------------------------------------------------------
def fence_items(fence: object) -> tuple[MissionItem, ...]:
    """The plan's "geoFence" as fence items, in the order QGC uploads them."""
    _versioned(fence, "geoFence", FENCE_VERSION)
    polygons, circles = _list(fence, "polygons", "geoFence"), _list(fence, "circles", "geoFence")
    items: list[MissionItem] = []
    for n, polygon in enumerate(polygons):
        where = f"geoFence.polygons[{n}]"
        inclusion, vertices = _shape(polygon, where, "polygon", list, "a list of [lat, lon]")
        if not MIN_POLYGON_VERTICES <= len(vertices) <= MAX_POLYGON_VERTICES:
            raise PlanError(f"{where}.polygon: {len(vertices)} vertices; a polygon has "
                            f"{MIN_POLYGON_VERTICES} to {MAX_POLYGON_VERTICES}")
        for i, vertex in enumerate(vertices):
            lat, lon, _ = _coordinate(vertex, f"{where}.polygon[{i}]", altitude=False)
            items.append(MissionItem(VERTEX[inclusion], FENCE_FRAME, 0, 0, float(len(vertices)), x=lat, y=lon))
    for n, circle in enumerate(circles):
        where = f"geoFence.circles[{n}]"
        inclusion, body = _shape(circle, where, "circle", dict, '{"center": [lat, lon], "radius": metres}')
        lat, lon, _ = _coordinate(body.get("center"), f"{where}.circle.center", altitude=False)
        radius = body.get("radius")
        if not _is_number(radius) or not _float32(radius) > 0:  # 1e-50 would go out as 0.0
            raise PlanError(f"{where}.circle.radius: {repr(radius)[:20]}; expected a finite number of metres > 0")
        items.append(MissionItem(CIRCLE[inclusion], FENCE_FRAME, 0, 0, float(radius), x=lat, y=lon))
    if "breachReturn" in fence:
        lat, lon, alt = _coordinate(fence["breachReturn"], "geoFence.breachReturn", altitude=True)
        items.append(MissionItem(M.MAV_CMD_NAV_FENCE_RETURN_POINT, POINT_FRAME, 0, 0, x=lat, y=lon, z=alt))
    return tuple(items)


def rally_items(rally: object) -> tuple[MissionItem, ...]:
    """The plan's "rallyPoints" as rally items."""
    _versioned(rally, "rallyPoints", RALLY_VERSION)
    items = []
    for n, point in enumerate(_list(rally, "points", "rallyPoints")):
        where = f"rallyPoints.points[{n}]"
        lat, lon, alt = _coordinate(point, where, altitude=True)
        if not INT16_MIN <= alt <= INT16_MAX:
            raise PlanError(f"{where}: altitude {alt:g} m; a rally point's is {INT16_MIN}..{INT16_MAX} m")
        items.append(MissionItem(M.MAV_CMD_NAV_RALLY_POINT, POINT_FRAME, 0, 0, x=lat, y=lon, z=alt))
    return tuple(items)


def _versioned(part: object, name: str, version: int) -> None:
    if not isinstance(part, dict):
        raise PlanError(f"{name}: expected an object")
    if part.get("version") != version or isinstance(part.get("version"), bool):
        raise PlanError(f"{name}.version: {part.get('version')!r}, only version {version} is read")


def _list(part: dict, key: str, name: str) -> list:
    value = part.get(key)
    if not isinstance(value, list):
        raise PlanError(f"{name}.{key}: expected a list")
    return value


def _shape(shape: object, where: str, key: str, kind: type, expected: str) -> tuple[bool, object]:
    """A polygon's or circle's keys: version 1 (if given), inclusion, and its `key` of type `kind`."""
    if not isinstance(shape, dict):
        raise PlanError(f"{where}: expected an object")
    version = shape.get("version", SHAPE_VERSION)
    if version != SHAPE_VERSION or isinstance(version, bool):
        raise PlanError(f"{where}.version: {version!r}, only version {SHAPE_VERSION} is read")
    inclusion = shape.get("inclusion")
    if not isinstance(inclusion, bool):
        raise PlanError(f"{where}.inclusion: expected true or false")
    body = shape.get(key)
    if not isinstance(body, kind):
        raise PlanError(f"{where}.{key}: expected {expected}")
    return inclusion, body


def _is_number(value: object) -> bool:
    """A JSON number a MISSION_ITEM_INT can carry: not NaN, infinite (1e999), nor an integer too
    large for a float (10**400, which math.isfinite cannot even take)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and abs(value) <= FLOAT32_MAX


def _float32(value: float) -> float:
    """The value as a MISSION_ITEM_INT param carries it."""
    return struct.unpack("<f", struct.pack("<f", value))[0]


def _coordinate(value: object, where: str, altitude: bool) -> tuple[int, int, float]:
    """[lat, lon] or [lat, lon, alt] -> (lat degE7, lon degE7, alt m or 0.0)."""
    shape = "[lat, lon, alt]" if altitude else "[lat, lon]"
    if not isinstance(value, list) or len(value) != (3 if altitude else 2):
        raise PlanError(f"{where}: expected {shape}")
    for v in value:
        if not _is_number(v):
            raise PlanError(f"{where}: {repr(v)[:20]} in {shape}; expected finite numbers (null is NaN)")
    lat, lon = value[0], value[1]
    if not -90 <= lat <= 90:
        raise PlanError(f"{where}: latitude {lat} out of -90..90")
    if not -180 <= lon <= 180:
        raise PlanError(f"{where}: longitude {lon} out of -180..180")
    alt = float(value[2]) if altitude else 0.0
    if not abs(alt) < LOCATION_ALT_MAX_M:
        raise PlanError(f"{where}: altitude {alt:g} m beyond +-{LOCATION_ALT_MAX_M:g}")
    return round(lat * 1e7), round(lon * 1e7), alt


# --- writing -------------------------------------------------------------------------------------
def fence_json(items: tuple[MissionItem, ...]) -> dict:
    """Fence items (as stored: valid) as QGC's "geoFence"."""
    polygons, circles, fence = [], [], {"version": FENCE_VERSION}
    seq = 0
    while seq < len(items):
        item = items[seq]
        if item.command in VERTEX_COMMANDS:
            run = items[seq:seq + int(item.param1)]
            polygons.append({"version": SHAPE_VERSION, "inclusion": item.command == VERTEX[True],
                             "polygon": [[v.x / 1e7, v.y / 1e7] for v in run]})
            seq += max(len(run), 1)
            continue
        if item.command in CIRCLE_COMMANDS:
            circles.append({"version": SHAPE_VERSION, "inclusion": item.command == CIRCLE[True],
                            "circle": {"center": [item.x / 1e7, item.y / 1e7], "radius": item.param1}})
        elif item.command == M.MAV_CMD_NAV_FENCE_RETURN_POINT:
            fence["breachReturn"] = [item.x / 1e7, item.y / 1e7, item.z]
        seq += 1
    fence.update(polygons=polygons, circles=circles)
    return fence


def rally_json(items: tuple[MissionItem, ...]) -> dict:
    return {"version": RALLY_VERSION, "points": [[i.x / 1e7, i.y / 1e7, i.z] for i in items]}
