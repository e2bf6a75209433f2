"""QGroundControl `.plan` files (version 2 missions) to and from gcsd's mission items.

A plan (QGC's `PlanMasterController`, `MissionController::_loadJsonFile`): `{"fileType": "Plan",
"version": 1, "groundStation", "mission": {"version": 2, "items": [...], "plannedHomePosition":
[lat, lon, alt], "firmwareType", "vehicleType", "cruiseSpeed", "hoverSpeed"}, "geoFence",
"rallyPoints"}`. Each mission item is a `SimpleItem`: `{"type": "SimpleItem", "command",
"frame", "autoContinue", "doJumpId", "params": [p1, p2, p3, p4, x, y, z]}`; QGC writes NaN as
null. The mission's item 0 is home (plannedHomePosition); the plan's items become 1..N after it.

x and y are degrees for a command with a location in a global frame (stored as degE7, as
MISSION_ITEM_INT carries them) and plain parameters otherwise (stored as integers, as
gcsd.vehicle.mission.items keeps them). The geoFence and rallyPoints are gcsd.api.http.planfence's; a plan
without one of them (QGC always writes both) leaves that plan of the vehicle as it is.

Reading is strict: a complex item (survey, corridor scan), a missing or mistyped key, a number
beyond a 32-bit float (it would go out as infinity) raises `PlanError` with where it is, and
nothing is changed; the stores' own upload checks (gcsd.vehicle.mission.stores) come after, for the
three plans together (gcsd.vehicle.mission.together).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.api.http.planfence import FLOAT32_MAX, PlanError, fence_items, fence_json, rally_items, rally_json
from gcsd.vehicle.mission.items import GLOBAL_FRAMES, MissionItem, has_location

FIRMWARE_ARDUPILOT = M.MAV_AUTOPILOT_ARDUPILOTMEGA
Items = tuple[MissionItem, ...]
__all__ = ["Plan", "PlanError", "from_plan", "to_plan"]


@dataclass(frozen=True, slots=True)
class Plan:
    mission: Items  # the items after home
    fence: Items | None  # None: the document has no geoFence (the vehicle's stays)
    rally: Items | None


def _number(value: float) -> float | None:
    return value if math.isfinite(value) else None


def _xy_out(item: MissionItem) -> tuple[float, float]:
    if has_location(item.command) and item.frame in GLOBAL_FRAMES:
        return item.x / 1e7, item.y / 1e7
    return float(item.x), float(item.y)


def to_plan(items: Items, home: MissionItem, vehicle_type: int, fence: Items = (), rally: Items = ()) -> dict:
    """The mission (item 0 = home, then the plan), fence and rally as a QGroundControl .plan."""
    entries = []
    for n, item in enumerate(items[1:], start=1):
        x, y = _xy_out(item)
        params = [item.param1, item.param2, item.param3, item.param4, x, y, item.z]
        entries.append({
            "type": "SimpleItem", "autoContinue": bool(item.autocontinue), "command": item.command,
            "doJumpId": n, "frame": item.frame, "params": [_number(v) for v in params],
        })
    return {
        "fileType": "Plan",
        "groundStation": "gcsd",
        "version": 1,
        "geoFence": fence_json(fence),
        "rallyPoints": rally_json(rally),
        "mission": {
            "version": 2,
            "firmwareType": FIRMWARE_ARDUPILOT,
            "vehicleType": vehicle_type,
            "cruiseSpeed": 15,
            "hoverSpeed": 5,
            "plannedHomePosition": [home.x / 1e7, home.y / 1e7, home.z],
            "items": entries,
        },
    }


def from_plan(document: object) -> Plan:
    """The plan's mission items (without home), fence and rally items. Raises PlanError."""
    if not isinstance(document, dict) or document.get("fileType") != "Plan":
        raise PlanError('not a QGroundControl plan (expected "fileType": "Plan")')
    mission = document.get("mission")
    if not isinstance(mission, dict):
        raise PlanError("mission: expected an object")
    if mission.get("version") != 2:
        raise PlanError(f"mission.version: {mission.get('version')!r}, only version 2 is read")
    raw_items = mission.get("items")
    if not isinstance(raw_items, list):
        raise PlanError("mission.items: expected a list")
    items = tuple(_item(raw, f"mission.items[{n}]") for n, raw in enumerate(raw_items))
    fence = fence_items(document["geoFence"]) if "geoFence" in document else None
    rally = rally_items(document["rallyPoints"]) if "rallyPoints" in document else None
    return Plan(items, fence, rally)


def _item(raw: object, where: str) -> MissionItem:
    if not isinstance(raw, dict):
        raise PlanError(f"{where}: expected an object")
    if raw.get("type") != "SimpleItem":
        raise PlanError(f"{where}: type {raw.get('type')!r}: only SimpleItem is taken (complex items such as "
                        "surveys are made into simple ones by QGroundControl before an upload)")
    command, frame = raw.get("command"), raw.get("frame")
    for key, value, top in (("command", command, 0xFFFF), ("frame", frame, 0xFF)):  # uint16, uint8 on the wire
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= top:
            raise PlanError(f"{where}.{key}: expected an integer 0..{top}")
    auto = raw.get("autoContinue", True)
    if not isinstance(auto, bool):
        raise PlanError(f"{where}.autoContinue: expected true or false")
    params = raw.get("params")
    if not isinstance(params, list) or len(params) != 7:
        raise PlanError(f"{where}.params: expected a list of 7 numbers (null for NaN)")
    values = []
    for i, p in enumerate(params):
        if p is None:
            values.append(math.nan)
        elif isinstance(p, bool) or not isinstance(p, (int, float)):
            raise PlanError(f"{where}.params[{i}]: expected a number or null")
        elif not abs(p) <= FLOAT32_MAX:  # infinity too (1e999 in JSON)
            raise PlanError(f"{where}.params[{i}]: {repr(p)[:20]} is beyond a 32-bit float")
        else:
            values.append(float(p))
    x, y = values[4], values[5]
    if not (math.isfinite(x) and math.isfinite(y)):
        raise PlanError(f"{where}.params: x and y must be numbers")
    if has_location(command) and frame in GLOBAL_FRAMES:
        xi, yi = round(x * 1e7), round(y * 1e7)
    else:
        xi, yi = int(x), int(y)
    if not (-2**31 <= xi < 2**31 and -2**31 <= yi < 2**31):
        raise PlanError(f"{where}.params: x or y out of range")
    return MissionItem(command, frame, 0, int(auto), values[0], values[1], values[2], values[3], xi, yi, values[6])
