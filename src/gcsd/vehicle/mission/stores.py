"""The three plans a vehicle holds: mission, fence and rally. Data and validation, no protocol.

A store holds a tuple of `MissionItem`s and answers four questions for the transfer machine:
what is item `seq` (as a download serves it), is this one item acceptable (`check_item`: the
specific MAV_MISSION_RESULT, checked as each item arrives), is this whole plan acceptable
(`check_plan`: a reason for the STATUSTEXT, checked once the last item is in), and `replace`,
which saves the new plan through the injected `save` first (an OSError leaves the old plan in
place) and only then makes it the plan. Nothing here touches a file itself; `save` does.

- Mission (REFERENCE.md 7.2): item 0 is home. It is always readable, served as a NAV_WAYPOINT
  at the current home, and an uploaded item 0 is kept only for its `current` flag. The count
  includes home and is 0 after a clear until home is set again (`home_changed`). Location
  commands need a global frame and a valid latitude and longitude; a DO_JUMP target must be an
  item of the resulting plan other than home. `current` comes back as it was uploaded (ArduPilot
  recomputes it, unreliably); which item the vehicle is on is `current_seq` (MISSION_CURRENT).
- Fence (7.3): polygon vertices, circles and a return point, in global frames. Each item is
  checked as it arrives (UNSUPPORTED, UNSUPPORTED_FRAME, INVALID_PARAM1 for a vertex count
  above 255); the whole set on completion: polygons of at least 3 consecutive vertices of one
  type whose param1 all equal their number, circles with a radius > 0, at most one return
  point, valid coordinates. Items come back exactly as uploaded (ArduPilot drops the altitude
  and returns frame GLOBAL; keeping them lets a client read back what it wrote).
- Rally (7.4): NAV_RALLY_POINT only, global frames, latitude, longitude and an altitude that
  fits ArduPilot's int16 metres (INVALID_PARAM5_X / 6_Y / 7).

Every item of every plan first passes `items.check_values` (NaN and infinity refused with
INVALID_PARAM1..4 / INVALID_PARAM7, ArduPilot's sanity_check_params), so a plan holding such a
value is never stored, and a stored file holding one (written by an older gcsd) fails `load`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission.items import (
    GLOBAL_FRAMES,
    MissionItem,
    check_values,
    has_location,
    is_known_command,
    lat_ok,
    lon_ok,
)

ACCEPTED = M.MAV_MISSION_ACCEPTED
VERTEX_COMMANDS = frozenset({
    M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
})
CIRCLE_COMMANDS = frozenset({M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION})
FENCE_COMMANDS = VERTEX_COMMANDS | CIRCLE_COMMANDS | {M.MAV_CMD_NAV_FENCE_RETURN_POINT}
MISSION_LOCATION_FRAMES = GLOBAL_FRAMES | {M.MAV_FRAME_MISSION}
MAX_POLYGON_VERTICES = 255
MIN_POLYGON_VERTICES = 3
INT16_MIN, INT16_MAX = -32768, 32767

Items = tuple[MissionItem, ...]


def _no_save(items: Items) -> None:
    return None


class PlanStore:
    mission_type: int
    name: str  # file stem and log name
    label: str  # how texts name it

    def __init__(self, max_items: int, save: Callable[[Items], None] = _no_save) -> None:
        self.max_items = max_items
        self.save = save
        self._items: Items = ()

    def count(self) -> int:
        return len(self._items)

    def items(self) -> Items:
        """The plan as a download serves it."""
        return tuple(self.item(seq) for seq in range(self.count()))

    def stored(self) -> Items:
        return self._items

    def item(self, seq: int) -> MissionItem | None:
        return self._items[seq] if 0 <= seq < len(self._items) else None

    def check_item(self, item: MissionItem, seq: int, plan_count: int) -> int:
        return ACCEPTED

    def check_plan(self, items: Items) -> str | None:
        return None

    def replace(self, items: Items) -> None:
        """Save, then adopt; an OSError from `save` leaves the old plan in force."""
        items = tuple(items)
        self.save(self._served(items))
        self._adopt(items)

    def load(self, items: Items) -> str | None:
        """Adopt a plan read at start, if valid; else the reason it is not (and nothing changes)."""
        items = tuple(items)
        reason = validate(self, items)
        if reason is None:
            self._adopt(items)
        return reason

    def clear_refused(self) -> bool:
        return False

    def completed_text(self) -> str | None:
        return None

    def _served(self, items: Items) -> Items:
        return items

    def _adopt(self, items: Items) -> None:
        self._items = items


def validate(store: PlanStore, items: Items) -> str | None:
    """Every check an upload would make, for a whole plan (a file read at start)."""
    if len(items) > store.max_items:
        return f"{len(items)} items, but only {store.max_items} are supported"
    for seq, item in enumerate(items):
        result = store.check_item(item, seq, len(items))
        if result != ACCEPTED:
            return f"item {seq}: {M.enums['MAV_MISSION_RESULT'][result].name}"
    return store.check_plan(items)


class MissionStore(PlanStore):
    mission_type = M.MAV_MISSION_TYPE_MISSION
    name = "mission"
    label = "Mission"

    def __init__(self, max_items: int, home: Callable[[], MissionItem],
                 save: Callable[[Items], None] = _no_save,
                 clear_refused: Callable[[], bool] = lambda: False) -> None:
        super().__init__(max_items, save)
        self.home = home
        self._clear_refused = clear_refused
        self.current_seq = 0

    def item(self, seq: int) -> MissionItem | None:
        if seq == 0:  # home: always readable, even with no plan
            flag = self._items[0].current if self._items else 0
            return _with_current(self.home(), flag)
        return super().item(seq)

    def home_changed(self) -> None:
        """Home was set: with no plan the mission becomes home alone (count 1)."""
        if not self._items:
            self._items = (self.home(),)

    def check_item(self, item: MissionItem, seq: int, plan_count: int) -> int:
        if seq == 0:
            return ACCEPTED  # replaced by home
        values = check_values(item)  # before the command is looked at, as ArduPilot
        if values != ACCEPTED:
            return values
        if not is_known_command(item.command):
            return M.MAV_MISSION_UNSUPPORTED
        if has_location(item.command):
            if item.frame not in MISSION_LOCATION_FRAMES:
                return M.MAV_MISSION_UNSUPPORTED_FRAME
            if not lat_ok(item.x):
                return M.MAV_MISSION_INVALID_PARAM5_X
            if not lon_ok(item.y):
                return M.MAV_MISSION_INVALID_PARAM6_Y
        if item.command == M.MAV_CMD_DO_JUMP:
            target = item.param1
            if not math.isfinite(target) or target < 1 or target >= plan_count:
                return M.MAV_MISSION_ERROR
        return ACCEPTED

    def set_current(self, seq: int) -> bool:
        if not 0 <= seq < self.count():
            return False
        self.current_seq = seq
        return True

    def clear_refused(self) -> bool:
        return self._clear_refused()

    def completed_text(self) -> str | None:
        return "Flight plan received"

    def _served(self, items: Items) -> Items:
        if not items:
            return items
        return (_with_current(self.home(), items[0].current), *items[1:])

    def _adopt(self, items: Items) -> None:
        super()._adopt(self._served(items))
        if self.current_seq >= len(self._items):
            self.current_seq = 0


def _with_current(item: MissionItem, current: int) -> MissionItem:
    if item.current == current:
        return item
    return MissionItem(item.command, item.frame, current, item.autocontinue, item.param1, item.param2,
                       item.param3, item.param4, item.x, item.y, item.z)


class FenceStore(PlanStore):
    mission_type = M.MAV_MISSION_TYPE_FENCE
    name = "fence"
    label = "Fence"

    def check_item(self, item: MissionItem, seq: int, plan_count: int) -> int:
        if item.command not in FENCE_COMMANDS:
            return M.MAV_MISSION_UNSUPPORTED
        if item.frame not in GLOBAL_FRAMES:
            return M.MAV_MISSION_UNSUPPORTED_FRAME
        values = check_values(item)  # a circle of radius NaN or inf, a vertex count NaN
        if values != ACCEPTED:
            return values
        if item.command in VERTEX_COMMANDS and not item.param1 <= MAX_POLYGON_VERTICES:
            return M.MAV_MISSION_INVALID_PARAM1
        return ACCEPTED

    def check_plan(self, items: Items) -> str | None:
        returns = 0
        seq = 0
        while seq < len(items):
            item = items[seq]
            if not (lat_ok(item.x) and lon_ok(item.y)):
                return f"Fence: item {seq} has an invalid location"
            if item.command in VERTEX_COMMANDS:
                reason = _polygon_problem(items, seq)
                if reason:
                    return reason
                seq += int(item.param1)
                continue
            if item.command in CIRCLE_COMMANDS and not item.param1 > 0:  # also NaN
                return f"Fence: circle at item {seq} needs a radius > 0"
            if item.command == M.MAV_CMD_NAV_FENCE_RETURN_POINT:
                returns += 1
                if returns > 1:
                    return f"Fence: second return point at item {seq} (at most one)"
            seq += 1
        return None


def _polygon_problem(items: Items, start: int) -> str | None:
    first = items[start]
    declared = first.param1
    if not (math.isfinite(declared) and declared == int(declared)) or declared < MIN_POLYGON_VERTICES:
        return f"Fence: polygon at item {start} declares {declared:g} vertices (needs at least 3)"
    n = int(declared)
    for seq in range(start, start + n):
        if seq >= len(items) or items[seq].command != first.command or items[seq].param1 != declared:
            return f"Fence: polygon at item {start} declares {n} vertices but has {seq - start}"
        if not (lat_ok(items[seq].x) and lon_ok(items[seq].y)):
            return f"Fence: item {seq} has an invalid location"
    return None


class RallyStore(PlanStore):
    mission_type = M.MAV_MISSION_TYPE_RALLY
    name = "rally"
    label = "Rally"

    def check_item(self, item: MissionItem, seq: int, plan_count: int) -> int:
        if item.command != M.MAV_CMD_NAV_RALLY_POINT:
            return M.MAV_MISSION_UNSUPPORTED
        if item.frame not in GLOBAL_FRAMES:
            return M.MAV_MISSION_UNSUPPORTED_FRAME
        values = check_values(item)
        if values != ACCEPTED:
            return values
        if not lat_ok(item.x):
            return M.MAV_MISSION_INVALID_PARAM5_X
        if not lon_ok(item.y):
            return M.MAV_MISSION_INVALID_PARAM6_Y
        if not (math.isfinite(item.z) and INT16_MIN <= item.z <= INT16_MAX):
            return M.MAV_MISSION_INVALID_PARAM7
        return ACCEPTED
