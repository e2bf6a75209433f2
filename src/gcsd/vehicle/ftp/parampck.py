"""`@PARAM/param.pck`: ArduPilot's packed parameter file (AP_Filesystem_Param.cpp; REFERENCE.md 6.1).

Layout, little-endian:

    header   u16 magic (0x671b; 0x671c with defaults), u16 num_params, u16 total_params
    entry    u8  type (low nibble: 1 INT8, 2 INT16, 3 INT32, 4 FLOAT) | flags << 4
                 (flag bit 0: a default value follows the value)
             u8  common_len (low nibble: leading chars shared with the previous name)
                 | (tail_len - 1) << 4
             tail_len bytes of name (the part not shared), then the value (1, 2 or 4 bytes),
             then the default in the same type when flagged

A default is written only with `withdefaults=1` and only when it differs from the value
(compared as C floats, within FLT_EPSILON). A name equal to the previous one keeps a 1-char
tail. Zero bytes pad an entry when its end would fall 1..size-1 bytes past a read-block boundary,
so the last value written (the default when flagged) starts exactly on the boundary; readers skip
zero bytes where an entry should start (type 0 is never valid). The padding depends on the read
size, which is why a handle serves one read size (the first one) for its whole life.

Upload (writing the file sets parameters): magic must be 0x671b, total_params must equal the
file's length, flags must be 0 (no defaults); num_params entries follow. Zero padding is
skipped on upload too (ArduPilot's parser does not, MAVProxy never sends any).

Query of the file name: `param.pck?start=N&count=C&withdefaults=0|1` (N, C < 65535); a bad value
is EINVAL, unknown keys are ignored as ArduPilot's scanner ignores them.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Protocol

from pymavlink.dialects.v20 import ardupilotmega as M

MAGIC = 0x671B
MAGIC_WITH_DEFAULTS = 0x671C
HEADER = struct.Struct("<HHH")
MAX_UPLOAD_BYTES = 0xFFFF  # the upload header stores the file length in a u16
FLT_EPSILON = 1.1920928955078125e-07

TYPE_CODE = {M.MAV_PARAM_TYPE_INT8: 1, M.MAV_PARAM_TYPE_INT16: 2, M.MAV_PARAM_TYPE_INT32: 3,
             M.MAV_PARAM_TYPE_REAL32: 4}
CODE_FORMAT = {1: struct.Struct("<b"), 2: struct.Struct("<h"), 3: struct.Struct("<i"), 4: struct.Struct("<f")}
CODE_MAV_TYPE = {code: ptype for ptype, code in TYPE_CODE.items()}


class ParamLike(Protocol):
    name: str
    ptype: int
    value: float | int
    default: float | int


@dataclass(frozen=True, slots=True)
class PckQuery:
    start: int = 0
    count: int = 0  # 0: to the end
    with_defaults: bool = False


def parse_query(query: str) -> PckQuery | None:
    """The `?...` part of the name (without the '?'); None when a value is bad."""
    values = {"start": 0, "count": 0, "withdefaults": 0}
    for item in query.split("&") if query else ():
        key, sep, text = item.partition("=")
        if key not in values:
            continue
        if not sep or not text.isdigit():
            return None
        values[key] = int(text)
    if values["start"] >= 0xFFFF or values["count"] >= 0xFFFF or values["withdefaults"] > 1:
        return None
    return PckQuery(values["start"], values["count"], values["withdefaults"] == 1)


def _c_float(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", float(value)))[0]


def _pack_value(code: int, value: float) -> bytes:
    if code == 4:
        return CODE_FORMAT[4].pack(float(value))
    fmt = CODE_FORMAT[code]
    bits = fmt.size * 8
    return fmt.pack(((int(value) + (1 << (bits - 1))) % (1 << bits)) - (1 << (bits - 1)))


def encode(params: Iterable[ParamLike], total: int, query: PckQuery = PckQuery(), block: int = 239) -> bytes:
    """The whole file for reads of `block` bytes. `params` are all parameters in index order."""
    num = max(0, total - query.start)
    if query.count and num > query.count:
        num = query.count
    out = bytearray(HEADER.pack(MAGIC_WITH_DEFAULTS if query.with_defaults else MAGIC, num, total))
    last = b""
    for i, p in enumerate(params):
        if i < query.start:
            continue
        if i >= query.start + num:
            break
        name = p.name.encode("ascii")
        common = 0
        limit = min(len(name), len(last))
        while common < limit and name[common] == last[common]:
            common += 1
        if common == len(name):  # same name as before: keep a 1-character tail
            common -= 1
        tail = name[common:]
        code = TYPE_CODE[p.ptype]
        size = CODE_FORMAT[code].size
        add_default = query.with_defaults and not abs(_c_float(p.value) - _c_float(p.default)) <= FLT_EPSILON
        packed_len = 2 + len(tail) + size * (2 if add_default else 1)
        if size > 1:
            over = (len(out) + packed_len) % block
            if 0 < over < size:
                out += bytes(size - over)
        out.append(code | (int(add_default) << 4))
        out.append(common | ((len(tail) - 1) << 4))
        out += tail
        out += _pack_value(code, p.value)
        if add_default:
            out += _pack_value(code, p.default)
        last = name
    return bytes(out)


@dataclass(frozen=True, slots=True)
class UploadedParam:
    name: str
    ptype: int  # MAV_PARAM_TYPE
    value: float | int


def decode_upload(data: bytes) -> list[UploadedParam] | None:
    """The parameters of an uploaded file, or None when it is malformed (nothing is applied)."""
    if len(data) < HEADER.size:
        return None
    magic, num, total = HEADER.unpack_from(data)
    if magic != MAGIC or total != len(data):
        return None
    out: list[UploadedParam] = []
    pos, last = HEADER.size, b""
    for _ in range(num):
        while pos < len(data) and data[pos] == 0:
            pos += 1
        if len(data) - pos < 2:
            return None
        code, flags = data[pos] & 0x0F, data[pos] >> 4
        if code not in CODE_FORMAT or flags != 0:
            return None
        common, tail_len = data[pos + 1] & 0x0F, (data[pos + 1] >> 4) + 1
        fmt = CODE_FORMAT[code]
        if common > len(last) or common + tail_len > 16 or pos + 2 + tail_len + fmt.size > len(data):
            return None
        name = last[:common] + data[pos + 2:pos + 2 + tail_len]
        pos += 2 + tail_len
        (value,) = fmt.unpack_from(data, pos)
        pos += fmt.size
        if code == 4 and not math.isfinite(value):
            return None
        try:
            text = name.decode("ascii")
        except UnicodeDecodeError:
            return None
        out.append(UploadedParam(text, CODE_MAV_TYPE[code], value))
        last = name
    return out
