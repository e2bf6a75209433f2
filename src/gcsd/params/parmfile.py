"""`.parm` files: one `NAME VALUE` per line (MAVProxy and Mission Planner also write
`NAME,VALUE`), `#` comments. Reading reports every bad line with its number instead of giving
up or skipping silently; the caller logs them and keeps defaults for what could not be read.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

from .store import REAL32, ParamEntry

_LINE = re.compile(r"^\s*([A-Za-z0-9_]{1,16})[\s,]+([-+0-9.eE]+|nan|inf)\s*(?:#.*)?$")


@dataclass(frozen=True)
class ParmProblem:
    line: int
    text: str
    reason: str


def parse_parm(text: str) -> tuple[dict[str, float], list[ParmProblem]]:
    values: dict[str, float] = {}
    problems: list[ParmProblem] = []
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        m = _LINE.match(stripped)
        if not m:
            problems.append(ParmProblem(number, stripped[:80], "expected NAME VALUE"))
            continue
        try:
            value = float(m.group(2))
        except ValueError:
            problems.append(ParmProblem(number, stripped[:80], "value is not a number"))
            continue
        if math.isnan(value) or math.isinf(value):
            problems.append(ParmProblem(number, stripped[:80], "value is not finite"))
            continue
        values[m.group(1)] = value
    return values, problems


def read_parm(path: Path) -> tuple[dict[str, float], list[ParmProblem]]:
    raw = path.read_bytes()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("utf-8", "replace")
        values, problems = parse_parm(text)
        return values, [ParmProblem(0, "", "file is not valid UTF-8")] + problems
    return parse_parm(text)


def format_value(entry: ParamEntry) -> str:
    if entry.ptype == REAL32:
        return f"{entry.value:.7g}"
    return str(int(entry.value))


def format_parm(entries: list[ParamEntry]) -> str:
    return "".join(f"{e.name:<16} {format_value(e)}\n" for e in entries)
