"""QGC WPL 110 text: how plans are kept in state_dir (mission.waypoints, fence.waypoints, rally.waypoints).

The format MAVProxy's `wp save` / `wp load` and Mission Planner use: a "QGC WPL 110" line, then
one tab-separated line per item: seq, current, frame, command, param1..4, x, y, z, autocontinue.
Lines starting with '#' and blank lines are skipped. seq must count up from 0.

Precision is exact, unlike pymavlink's `mavwp.save` (six decimals, about 11 cm of latitude):
x/y of commands with a location are written as degrees with exactly seven decimals (the degE7
integer with a decimal point) and read back by rounding; other x/y are integers; params and z
with nine significant digits, which is exact for the float32 values MAVLink carries. Files
written by MAVProxy read fine. Reading is our own (mavwp's loader builds MISSION_ITEM messages
through mavutil's process-wide dialect choice and cannot load fence or rally types without it).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable

from gcsd.vehicle.mission.items import DEGREES_E7, LOCAL_FRAMES, LOCAL_SCALE, MissionItem, has_location

HEADER = "QGC WPL 110"
COLUMNS = 12


class WplError(ValueError):
    """A file that is not a valid WPL 110 plan; `line` is 1-based."""

    def __init__(self, line: int, reason: str) -> None:
        super().__init__(f"line {line}: {reason}")
        self.line = line
        self.reason = reason


def _fixed7(value: int) -> str:
    sign = "-" if value < 0 else ""
    whole, frac = divmod(abs(value), 10**7)
    return f"{sign}{whole}.{frac:07d}"


def _scale(item: MissionItem) -> float | None:
    if not has_location(item.command):
        return None
    return LOCAL_SCALE if item.frame in LOCAL_FRAMES else DEGREES_E7


def _xy_text(item: MissionItem, value: int) -> str:
    scale = _scale(item)
    if scale is None:
        return str(value)
    if scale == DEGREES_E7:
        return _fixed7(value)
    return f"{value / scale:.4f}"


def _num(value: float) -> str:
    return f"{value:.9g}"


def _f32(value: float) -> float:
    """The float32 a MAVLink field would carry (what a decoded message holds)."""
    try:
        return struct.unpack("<f", struct.pack("<f", value))[0]
    except OverflowError:
        return value


def dumps(items: Iterable[MissionItem]) -> str:
    lines = [HEADER]
    for seq, it in enumerate(items):
        lines.append("\t".join((
            str(seq), str(it.current), str(it.frame), str(it.command),
            _num(it.param1), _num(it.param2), _num(it.param3), _num(it.param4),
            _xy_text(it, it.x), _xy_text(it, it.y), _num(it.z), str(it.autocontinue),
        )))
    return "\n".join(lines) + "\n"


def loads(text: str) -> list[MissionItem]:
    lines = text.splitlines()
    if not lines or lines[0].strip() != HEADER:
        got = lines[0].strip()[:40] if lines else "an empty file"
        raise WplError(1, f"expected the header {HEADER!r}, got {got!r}")
    items: list[MissionItem] = []
    for number, line in enumerate(lines[1:], start=2):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.split()
        if len(fields) != COLUMNS:
            raise WplError(number, f"expected {COLUMNS} values, got {len(fields)}")
        try:
            seq, current, frame, command = (int(v) for v in fields[:4])
            param1, param2, param3, param4, x, y, z = (float(v) for v in fields[4:11])
            param1, param2, param3, param4, z = (_f32(v) for v in (param1, param2, param3, param4, z))
            autocontinue = int(fields[11])
        except ValueError as exc:
            raise WplError(number, str(exc)) from None
        if seq != len(items):
            raise WplError(number, f"expected seq {len(items)}, got {seq}")
        probe = MissionItem(command, frame)
        scale = _scale(probe)
        try:
            xi, yi = (round(x * scale), round(y * scale)) if scale else (int(x), int(y))
        except (ValueError, OverflowError):
            raise WplError(number, "x or y is not a finite number") from None
        if not (-2**31 <= xi < 2**31 and -2**31 <= yi < 2**31):
            raise WplError(number, "x or y out of range")
        items.append(MissionItem(command, frame, current, autocontinue, param1, param2, param3, param4,
                                 xi, yi, z))
    return items
