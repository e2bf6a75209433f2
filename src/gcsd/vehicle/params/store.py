"""The typed parameter store: definitions as data, values as the C types ArduPilot uses.

Types are MAV_PARAM_TYPE INT8, INT16, INT32 and REAL32. Values travel as C-cast floats. A
PARAM_SET value becomes an integer as AP_Param::set_float does: nudged by 0.01 away from zero,
truncated, clamped to the type's range; a REAL32 is rounded to single precision. As in
ArduPilot (GCS_Param.cpp refuses only NaN and infinity), a finite value outside the documented
range (`min`/`max`, advice that ground stations show) is stored: what acts on a parameter clamps
it where it acts, and the pre-arm checks report the dangerous ones ("PreArm: Check ANGLE_MAX").
OUT_OF_RANGE is left for a REAL32 beyond single precision (from a file; the wire cannot carry one).

Listeners registered with `on_change(name, fn)` run after a value changes, so changing a
parameter changes behaviour at once (stream rates, GCS sysid, checks).
"""

from __future__ import annotations

import enum
import math
import struct
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as M

INT8, INT16, INT32, REAL32 = (
    M.MAV_PARAM_TYPE_INT8, M.MAV_PARAM_TYPE_INT16, M.MAV_PARAM_TYPE_INT32, M.MAV_PARAM_TYPE_REAL32,
)
TYPE_RANGE = {INT8: (-128, 127), INT16: (-32768, 32767), INT32: (-(2**31), 2**31 - 1)}
NAME_MAX = 16


@dataclass(frozen=True)
class ParamDef:
    name: str
    ptype: int
    default: float
    min: float | None = None
    max: float | None = None
    units: str = ""
    description: str = ""
    read_only: bool = False
    reboot: bool = False  # takes effect at the next start


class SetResult(enum.Enum):
    CHANGED = "changed"
    UNCHANGED = "unchanged"
    UNKNOWN = "unknown"
    INVALID = "invalid"  # NaN or infinity
    READ_ONLY = "read_only"
    OUT_OF_RANGE = "out_of_range"


@dataclass(frozen=True, slots=True)
class ParamEntry:
    name: str
    ptype: int
    value: float | int
    default: float | int
    index: int


def to_type(ptype: int, value: float) -> float | int:
    """A float as the C type would hold it (AP_Param::set_float)."""
    if ptype == REAL32:
        return struct.unpack("<f", struct.pack("<f", value))[0]
    lo, hi = TYPE_RANGE[ptype]
    nudged = value + (0.01 if value >= 0 else -0.01)
    return int(max(lo, min(hi, nudged)))


def fits_real32(value: float) -> bool:
    """A finite double that rounds to a finite single-precision float (|v| up to ~3.4028235e38)."""
    try:
        struct.pack("<f", value)
    except OverflowError:
        return False
    return True


def as_float(value: float) -> float:
    """The C cast a PARAM_VALUE carries."""
    return struct.unpack("<f", struct.pack("<f", float(value)))[0]


class ParamStore:
    def __init__(self, defs: Iterable[ParamDef]) -> None:
        ordered = list(defs)  # ArduPilot's index order, as the definitions come (gcsd.vehicle.params.defs)
        names = [d.name for d in ordered]
        if len(set(names)) != len(names):
            raise ValueError("duplicate parameter names")
        for d in ordered:
            if not d.name or len(d.name) > NAME_MAX:
                raise ValueError(f"bad parameter name {d.name!r}")
        self._defs = ordered
        self._index = {d.name: i for i, d in enumerate(ordered)}
        self._values: list[float | int] = [to_type(d.ptype, d.default) for d in ordered]
        self._listeners: dict[str, list[Callable[[str, float | int], None]]] = {}

    def __len__(self) -> int:
        return len(self._defs)

    def __contains__(self, name: str) -> bool:
        return name in self._index

    def definition(self, name: str) -> ParamDef:
        return self._defs[self._index[name]]

    def index_of(self, name: str) -> int | None:
        return self._index.get(name)

    def get(self, name: str) -> float | int:
        return self._values[self._index[name]]

    def clamped(self, name: str) -> float | int:
        """The value within its documented range: what the simulation acts on (the stored value
        may lie outside it, as ArduPilot's may; the pre-arm checks read the stored one)."""
        d = self._defs[self._index[name]]
        value = self._values[self._index[name]]
        if d.min is not None and value < d.min:
            return d.min if d.ptype == REAL32 else int(d.min)
        if d.max is not None and value > d.max:
            return d.max if d.ptype == REAL32 else int(d.max)
        return value

    def entry(self, index: int) -> ParamEntry | None:
        if not 0 <= index < len(self._defs):
            return None
        d = self._defs[index]
        return ParamEntry(d.name, d.ptype, self._values[index], to_type(d.ptype, d.default), index)

    def entry_by_name(self, name: str) -> ParamEntry | None:
        index = self._index.get(name)
        return None if index is None else self.entry(index)

    def entries(self) -> Iterator[ParamEntry]:
        for i in range(len(self._defs)):
            yield self.entry(i)

    def on_change(self, name: str, fn: Callable[[str, float | int], None]) -> None:
        self._listeners.setdefault(name, []).append(fn)

    def set(self, name: str, value: float, force: bool = False) -> SetResult:
        """Set from a ground station (force=True: from our own code: read-only allowed)."""
        index = self._index.get(name)
        if index is None:
            return SetResult.UNKNOWN
        if not isinstance(value, (int, float)) or math.isnan(value) or math.isinf(value):
            return SetResult.INVALID
        d = self._defs[index]
        if d.read_only and not force:
            return SetResult.READ_ONLY
        if d.ptype == REAL32 and not fits_real32(value):  # from a file or a double, never from the wire
            return SetResult.OUT_OF_RANGE
        typed = to_type(d.ptype, value)
        if typed == self._values[index]:
            return SetResult.UNCHANGED
        self._values[index] = typed
        for fn in self._listeners.get(name, ()):
            fn(name, typed)
        return SetResult.CHANGED

    def changed_from_default(self) -> list[ParamEntry]:
        return [e for e in self.entries() if e.value != e.default]
