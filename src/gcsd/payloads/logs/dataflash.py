"""DataFlash (`.BIN`) records, written as ArduPilot's AP_Logger writes them.

A record is the two head bytes 0xA3 0x95, a one-byte type and a little-endian packed body. The
type's layout is declared by an FMT record (type 128: Type, Length, Name, Format, Columns) that
precedes the first record of that type; FMT describes itself first. UNIT and MULT records name
the unit and multiplier letters, and an FMTU record per type gives each column's unit and
multiplier, which is what pymavlink's DFReader, mavlogdump.py and MAVExplorer read to show
`m`, `deg` or `A` beside a value.

Format letters (ArduPilot's LogStructure.h): b B h H i I q Q integers, f float, d double,
n char[4], N char[16], Z char[64], c/C int16/uint16 x100, e/E int32/uint32 x100, L int32 degrees
x1e7, M uint8 flight mode. Scaled letters take the physical value here (`c` 12.34 -> 1234).

`RecordFormat` is one type; `DataFlashWriter` holds a table of them and packs records. Pure: no
clock, no file; callers pass `time_us` as the first column where the format has one.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

HEAD = b"\xa3\x95"
FMT_TYPE = 128
FMT_LENGTH = 89  # 3 head bytes + B B 4s 16s 64s

_STRUCT = {"b": "b", "B": "B", "h": "h", "H": "H", "i": "i", "I": "I", "q": "q", "Q": "Q", "f": "f",
           "d": "d", "n": "4s", "N": "16s", "Z": "64s", "c": "h", "C": "H", "e": "i", "E": "I", "L": "i",
           "M": "B"}
_SCALE = {"c": 100.0, "C": 100.0, "e": 100.0, "E": 100.0, "L": 1e7}
_TEXT = {"n": 4, "N": 16, "Z": 64}
_INT_RANGE = {"b": (-128, 127), "B": (0, 255), "h": (-32768, 32767), "H": (0, 65535), "c": (-32768, 32767),
              "C": (0, 65535), "M": (0, 255), "i": (-2**31, 2**31 - 1), "e": (-2**31, 2**31 - 1),
              "L": (-2**31, 2**31 - 1), "I": (0, 2**32 - 1), "E": (0, 2**32 - 1),
              "q": (-2**63, 2**63 - 1), "Q": (0, 2**64 - 1)}

# ArduPilot's unit and multiplier letters (the subset these records use)
UNITS = {"-": "", "#": "instance", "s": "s", "m": "m", "n": "m/s", "d": "deg", "h": "degheading",
         "D": "deglatitude", "U": "deglongitude", "v": "V", "A": "A", "a": "Ah", "%": "%",
         "S": "satellites", "O": "degC", "J": "W.s", "w": "Ohm"}
MULTS = {"-": 0.0, "?": 1.0, "0": 1.0, "F": 1e-6, "C": 1e-3, "B": 1e-2, "A": 1e-1, "G": 1e-7}


@dataclass(frozen=True)
class RecordFormat:
    type: int
    name: str
    format: str
    columns: tuple[str, ...]
    units: str = ""  # one UNITS letter per column ("" leaves the record without an FMTU)
    mults: str = ""  # one MULTS letter per column

    def __post_init__(self) -> None:
        if len(self.format) != len(self.columns) or any(c not in _STRUCT for c in self.format):
            raise ValueError(f"{self.name}: format {self.format!r} does not match {len(self.columns)} columns")
        if self.units and (len(self.units) != len(self.format) or len(self.mults) != len(self.format)):
            raise ValueError(f"{self.name}: units/mults must have one letter per column")
        if len(self.name) > 4 or not 0 <= self.type <= 255:
            raise ValueError(f"{self.name}: names are at most 4 characters, types 0..255")
        object.__setattr__(self, "_struct", struct.Struct("<" + "".join(_STRUCT[c] for c in self.format)))

    @property
    def length(self) -> int:
        """The whole record's length, head bytes included (FMT's Length column)."""
        return 3 + self._struct.size

    def pack(self, values) -> bytes:
        if len(values) != len(self.format):
            raise ValueError(f"{self.name}: {len(values)} values for {len(self.format)} columns")
        return HEAD + bytes((self.type,)) + self._struct.pack(*(_field(c, v) for c, v in zip(self.format, values)))


def _field(code: str, value):
    if code in _TEXT:
        data = value.encode("ascii", "replace") if isinstance(value, str) else bytes(value)
        return data[:_TEXT[code]]
    if code in ("f", "d"):
        return float(value)
    scaled = float(value) * _SCALE.get(code, 1.0)
    if not math.isfinite(scaled):
        scaled = 0.0
    low, high = _INT_RANGE[code]
    return min(high, max(low, round(scaled)))


FMT = RecordFormat(FMT_TYPE, "FMT", "BBnNZ", ("Type", "Length", "Name", "Format", "Columns"))
UNIT = RecordFormat(177, "UNIT", "QbZ", ("TimeUS", "Id", "Label"))
MULT = RecordFormat(178, "MULT", "Qbd", ("TimeUS", "Id", "Mult"))
FMTU = RecordFormat(179, "FMTU", "QBNN", ("TimeUS", "FmtType", "UnitIds", "MultIds"))


class DataFlashWriter:
    """Packs the header (FMT of every type, UNIT, MULT, FMTU) and records by name."""

    def __init__(self, formats: tuple[RecordFormat, ...]) -> None:
        self.formats = {f.name: f for f in (FMT, UNIT, MULT, FMTU, *formats)}
        types = [f.type for f in self.formats.values()]
        if len(set(types)) != len(types):
            raise ValueError("two record formats share a type number")

    def header(self, time_us: int) -> bytes:
        """What a log starts with: every FMT (FMT's own first), then units, multipliers and FMTUs."""
        out = [FMT.pack((f.type, f.length, f.name, f.format, ",".join(f.columns))) for f in self.formats.values()]
        out += [UNIT.pack((time_us, ord(k), v)) for k, v in UNITS.items()]
        out += [MULT.pack((time_us, ord(k), v)) for k, v in MULTS.items()]
        out += [FMTU.pack((time_us, f.type, f.units, f.mults)) for f in self.formats.values() if f.units]
        return b"".join(out)

    def record(self, name: str, *values) -> bytes:
        return self.formats[name].pack(values)
