"""The geofence as a pure check: is this state inside the fence, and if not, which part?

Fence types (FENCE_TYPE bits, ArduPilot's): 1 maximum altitude above home (FENCE_ALT_MAX),
2 a circle of FENCE_RADIUS around home, 4 the polygons and circles of the fence plan
(inclusion zones must all contain the vehicle, exclusion zones must not), 8 minimum altitude
(FENCE_ALT_MIN, only checked in flight). `breaches` returns the set of breached types; an
empty set means inside. MAVLink's FENCE_BREACH codes for FENCE_STATUS come from `breach_code`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission.stores import CIRCLE_COMMANDS, VERTEX_COMMANDS
from gcsd.vehicle.sim.geo import distance_m, ne_m, point_in_polygon
from gcsd.vehicle.sim.state import VehicleState

ALT_MAX, CIRCLE, POLYGON, ALT_MIN = 1, 2, 4, 8
_NAMES = {ALT_MAX: "altitude fence", CIRCLE: "circular fence", POLYGON: "polygon fence", ALT_MIN: "minimum altitude"}


@dataclass(frozen=True)
class FenceConfig:
    enabled: bool = False
    types: int = ALT_MAX | CIRCLE | POLYGON
    alt_max_m: float = 100.0
    alt_min_m: float = -10.0
    radius_m: float = 300.0
    margin_m: float = 2.0

    @classmethod
    def from_params(cls, get: Callable[[str], float]) -> FenceConfig:
        """A vehicle type without some of these (Rover 4.6 has no FENCE_ALT_*) gets that fence off."""
        def opt(name: str, absent: float) -> float:
            try:
                return float(get(name))
            except KeyError:
                return absent
        return cls(bool(get("FENCE_ENABLE")), int(opt("FENCE_TYPE", 0)), opt("FENCE_ALT_MAX", math.inf),
                   opt("FENCE_ALT_MIN", -math.inf), opt("FENCE_RADIUS", math.inf), opt("FENCE_MARGIN", 0.0))


def breaches(s: VehicleState, cfg: FenceConfig, items: Iterable, ignore_min_alt: bool = False) -> set[int]:
    out: set[int] = set()
    rel = s.relative_alt_m
    if cfg.types & ALT_MAX and rel > cfg.alt_max_m:
        out.add(ALT_MAX)
    if cfg.types & ALT_MIN and not ignore_min_alt and not s.on_ground and rel < cfg.alt_min_m:
        out.add(ALT_MIN)
    if cfg.types & CIRCLE and distance_m(s.home_lat, s.home_lon, s.lat, s.lon) > cfg.radius_m:
        out.add(CIRCLE)
    if cfg.types & POLYGON and not _inside_plan(s, list(items)):
        out.add(POLYGON)
    return out


def _inside_plan(s: VehicleState, items: list) -> bool:
    seq = 0
    while seq < len(items):
        item = items[seq]
        if item.command in VERTEX_COMMANDS:
            count = max(int(item.param1), 1)
            vertices = [ne_m(s.lat, s.lon, v.x / 1e7, v.y / 1e7) for v in items[seq:seq + count]]
            inside = point_in_polygon(0.0, 0.0, vertices)
            if inside != (item.command == M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION):
                return False
            seq += count
            continue
        if item.command in CIRCLE_COMMANDS:
            inside = distance_m(s.lat, s.lon, item.x / 1e7, item.y / 1e7) <= item.param1
            if inside != (item.command == M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION):
                return False
        seq += 1
    return True


def describe(types: set[int]) -> str:
    return ", ".join(_NAMES[t] for t in sorted(types))


def breach_code(types: set[int]) -> int:
    """FENCE_BREACH for FENCE_STATUS: the first breached kind."""
    if ALT_MIN in types:
        return M.FENCE_BREACH_MINALT
    if ALT_MAX in types:
        return M.FENCE_BREACH_MAXALT
    if types:
        return M.FENCE_BREACH_BOUNDARY
    return M.FENCE_BREACH_NONE
