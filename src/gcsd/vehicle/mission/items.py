"""One mission item, as MISSION_ITEM_INT carries it, and the conversions to and from the wire.

A `MissionItem` is the MISSION_ITEM_INT payload without the addressing fields: seq is its place
in a plan and mission_type the plan it belongs to. Every store keeps items in this one form.

Legacy MISSION_ITEM (float x/y) is converted as ArduPilot's AP_Mission does: for commands that
carry a location (pymavlink's MAV_CMD `has_location`, the same test MAVProxy uses) x/y are
degrees, scaled by 1e7 in the global frames and metres scaled by 1e4 in the local frames; any
other frame is UNSUPPORTED_FRAME. For commands without a location x/y are plain parameters and
are truncated to integers. Downloads as MISSION_ITEM apply the inverse.

`check_values` is the one value check every plan item passes (upload, FTP write, a plan file
read at start, a guided "fly to" item), before any store-specific check: ArduPilot's
AP_Mission::sanity_check_params (params 1-4: infinity never, NaN only where `NAN_PARAMS` says
the command gives it a meaning, e.g. a waypoint's yaw) -> INVALID_PARAM1..4; z of a command
with a location finite and within +-83 000 m (ArduPilot's LOCATION_ALT_MAX_M) ->
INVALID_PARAM7. Better than ArduPilot, which drops z for other commands: gcsd stores items as
uploaded, so a NaN or infinite z is refused on every item (INVALID_PARAM7), never stored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache

from pymavlink.dialects.v20 import ardupilotmega as M

GLOBAL_FRAMES = frozenset({
    M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    M.MAV_FRAME_GLOBAL_INT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
})
LOCAL_FRAMES = frozenset({M.MAV_FRAME_LOCAL_NED, M.MAV_FRAME_LOCAL_ENU})
DEGREES_E7 = 1e7
LOCAL_SCALE = 1e4
LAT_LIMIT_E7 = 90 * 10**7
LON_LIMIT_E7 = 180 * 10**7
LOCATION_ALT_MAX_M = 83_000.0  # ArduPilot's Location: altitudes an int24 of centimetres can hold


@dataclass(frozen=True, slots=True)
class MissionItem:
    command: int
    frame: int = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    current: int = 0
    autocontinue: int = 1
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0  # latitude in degE7 for commands with a location, else param5 as an integer
    y: int = 0
    z: float = 0.0


# params (1-based) where ArduPilot's sanity_check_params lets NaN through ("use the current yaw" etc.)
NAN_PARAMS = {
    M.MAV_CMD_NAV_WAYPOINT: frozenset({4}),
    M.MAV_CMD_NAV_LAND: frozenset({4}),
    M.MAV_CMD_NAV_TAKEOFF: frozenset({4}),
    M.MAV_CMD_NAV_VTOL_TAKEOFF: frozenset({4}),
    M.MAV_CMD_NAV_VTOL_LAND: frozenset({3, 4}),
}
INVALID_PARAM = (M.MAV_MISSION_INVALID_PARAM1, M.MAV_MISSION_INVALID_PARAM2, M.MAV_MISSION_INVALID_PARAM3,
                 M.MAV_MISSION_INVALID_PARAM4)


def check_values(item: MissionItem) -> int:
    """MAV_MISSION_ACCEPTED, or the INVALID_PARAMn result for a value the item cannot honour."""
    nan_ok = NAN_PARAMS.get(item.command, frozenset())
    for n, value in enumerate((item.param1, item.param2, item.param3, item.param4), start=1):
        if math.isinf(value) or (math.isnan(value) and n not in nan_ok):
            return INVALID_PARAM[n - 1]
    if not math.isfinite(item.z) or (has_location(item.command) and abs(item.z) >= LOCATION_ALT_MAX_M):
        return M.MAV_MISSION_INVALID_PARAM7
    return M.MAV_MISSION_ACCEPTED


@cache
def has_location(command: int) -> bool:
    entry = M.enums["MAV_CMD"].get(command)
    return bool(entry is not None and getattr(entry, "has_location", True))


def is_known_command(command: int) -> bool:
    return command in M.enums["MAV_CMD"]


def lat_ok(x_e7: int) -> bool:
    return -LAT_LIMIT_E7 <= x_e7 <= LAT_LIMIT_E7


def lon_ok(y_e7: int) -> bool:
    return -LON_LIMIT_E7 <= y_e7 <= LON_LIMIT_E7


def from_item_int(msg) -> MissionItem:
    return MissionItem(
        msg.command, msg.frame, msg.current, msg.autocontinue,
        msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z,
    )


def from_item_float(msg) -> MissionItem | int:
    """A legacy MISSION_ITEM as an item, or the MAV_MISSION_RESULT that rejects it."""
    x, y = msg.x, msg.y
    if not math.isfinite(x):
        return M.MAV_MISSION_INVALID_PARAM5_X
    if not math.isfinite(y):
        return M.MAV_MISSION_INVALID_PARAM6_Y
    if has_location(msg.command):
        if msg.frame in GLOBAL_FRAMES or msg.frame == M.MAV_FRAME_MISSION:
            scale = DEGREES_E7
        elif msg.frame in LOCAL_FRAMES:
            scale = LOCAL_SCALE
        else:
            return M.MAV_MISSION_UNSUPPORTED_FRAME
        xi, yi = round(x * scale), round(y * scale)
    else:
        xi, yi = int(x), int(y)
    if not (-2**31 <= xi < 2**31):
        return M.MAV_MISSION_INVALID_PARAM5_X
    if not (-2**31 <= yi < 2**31):
        return M.MAV_MISSION_INVALID_PARAM6_Y
    return MissionItem(
        msg.command, msg.frame, msg.current, msg.autocontinue,
        msg.param1, msg.param2, msg.param3, msg.param4, xi, yi, msg.z,
    )


def _float_xy(item: MissionItem) -> tuple[float, float]:
    if has_location(item.command):
        scale = LOCAL_SCALE if item.frame in LOCAL_FRAMES else DEGREES_E7
        return item.x / scale, item.y / scale
    return float(item.x), float(item.y)


def item_int_message(item: MissionItem, seq: int, mission_type: int, target: tuple[int, int]):
    return M.MAVLink_mission_item_int_message(
        target[0], target[1], seq, item.frame, item.command, item.current, item.autocontinue,
        item.param1, item.param2, item.param3, item.param4, item.x, item.y, item.z, mission_type,
    )


def item_float_message(item: MissionItem, seq: int, mission_type: int, target: tuple[int, int]):
    x, y = _float_xy(item)
    return M.MAVLink_mission_item_message(
        target[0], target[1], seq, item.frame, item.command, item.current, item.autocontinue,
        item.param1, item.param2, item.param3, item.param4, x, y, item.z, mission_type,
    )
