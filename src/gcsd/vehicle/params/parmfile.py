"""`.parm` files: one `NAME VALUE` per line (MAVProxy and Mission Planner also write
`NAME,VALUE`), `#` comments. Reading reports every bad line with its number instead of giving
up or skipping silently; what the caller does with them depends on whose file it is (a
`params_file` from the configuration is refused as a whole, see preflight.py; the daemon's own
saved file keeps what it could read).

Writing: a REAL32 value is written with the fewest significant digits (6 to 9) that read back
as the very same single-precision float, so every value survives a restart bit-exact
(0.35000002 stays 0.35000002, not 0.35; 0.1 stays "0.1"); integers as integers.
"""

from __future__ import annotations

import math
import re
import struct
from dataclasses import dataclass
from pathlib import Path

from gcsd.vehicle.params.store import REAL32, ParamEntry

MAX_PARM_BYTES = 4 * 1024 * 1024  # 1 000 parameters take ~25 KB
_LINE = re.compile(r"^\s*([A-Za-z0-9_]{1,16})[\s,]+([-+0-9.eE]+|[-+]?(?i:nan|inf|infinity))\s*(?:#.*)?$")


@dataclass(frozen=True)
class ParmProblem:
    line: int
    text: str
    reason: str


@dataclass(frozen=True)
class ParmLine:
    line: int
    name: str
    value: float


def parse_parm_lines(text: str) -> tuple[list[ParmLine], list[ParmProblem]]:
    """Every good `NAME VALUE` line with its number, and every bad one."""
    values: list[ParmLine] = []
    problems: list[ParmProblem] = []
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        m = _LINE.match(stripped)
        if not m:
            problems.append(ParmProblem(number, stripped[:80], "expected NAME VALUE"))
            continue
        name, text = m.group(1), m.group(2)
        try:
            value = float(text)
        except ValueError:
            problems.append(ParmProblem(number, "", f"{name}: {text!r} is not a number"))
            continue
        if math.isnan(value) or math.isinf(value):
            problems.append(ParmProblem(number, "", f"{name}: {text} is not a finite number"))
            continue
        values.append(ParmLine(number, name, value))
    return values, problems


def parse_parm(text: str) -> tuple[dict[str, float], list[ParmProblem]]:
    lines, problems = parse_parm_lines(text)
    return {p.name: p.value for p in lines}, problems


def read_parm_lines(path: Path) -> tuple[list[ParmLine], list[ParmProblem]]:
    with open(path, "rb") as file:
        raw = file.read(MAX_PARM_BYTES + 1)
    if len(raw) > MAX_PARM_BYTES:
        return [], [ParmProblem(1, "", f"file is larger than {MAX_PARM_BYTES} bytes")]
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        values, problems = parse_parm_lines(raw.decode("utf-8", "replace"))
        return values, [ParmProblem(line, "", "file is not valid UTF-8")] + problems
    return parse_parm_lines(text)


def read_parm(path: Path) -> tuple[dict[str, float], list[ParmProblem]]:
    lines, problems = read_parm_lines(path)
    return {p.name: p.value for p in lines}, problems


def format_real32(value: float) -> str:
    """The shortest text that reads back as the same single-precision float."""
    single = struct.pack("<f", value)
    for digits in range(6, 10):
        text = f"{value:.{digits}g}"
        if struct.pack("<f", float(text)) == single:
            return text
    return f"{value:.9g}"  # not reached: 9 significant digits always round-trip a float32


def format_value(entry: ParamEntry) -> str:
    if entry.ptype == REAL32:
        return format_real32(entry.value)
    return str(int(entry.value))


def format_parm(entries: list[ParamEntry]) -> str:
    return "".join(f"{e.name:<16} {format_value(e)}\n" for e in entries)
