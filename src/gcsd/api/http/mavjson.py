"""mavlink2rest's JSON for MAVLink messages (ardupilotmega dialect), both ways, on pymavlink.

What mavlink2rest writes (rust-mavlink's serde, as its `src/data.rs` and Cockpit's reader use it;
REFERENCE.md section 18), and so what gcsd writes:

- a message is an object with `"type": NAME` first, then every field in wire order (pymavlink's
  `ordered_fieldnames`, extensions last); a field named `type` is written `mavtype`
  (rust-mavlink renames it: a keyword in Rust), in every message, not only HEARTBEAT;
- a field with an enum: `{"type": "ENTRY_NAME"}`; a value the dialect does not name is written
  as the bare integer (rust-mavlink cannot represent it and drops the whole message);
- a bitmask (the enum is a bitmask, or any field shows it with `display="bitmask"`, rust-mavlink's
  `update_enums` rule): `{"bits": N}` (SPEC.md pins this form; Cockpit reads `base_mode.bits`);
- a char[N] field: a list of N one-character strings, NUL-padded (Cockpit:
  `param_id.join('').replace(/\\0/g, '')`); other arrays: lists of numbers;
- NaN and infinities: null (what serde_json writes for them).

Reading (`POST /v1/mavlink`, WebSocket text frames): `{"header": {...}, "message": {...}}`.
Besides the forms above it takes a bare integer for an enum or a bitmask, an entry name as a
string for an enum, `"A | B"` flag names for a bitmask (current mavlink2rest writes those), and a
plain string or a list of integers for a char[N] field. A missing field is 0 (the template's
value); an unknown field, a value of the wrong type, an integer out of its type's range, a float
that is not finite or does not fit a float32, an enum entry from another enum: `BadMessage`
naming the field. An unknown message name is `UnknownMessage` (404, "Invalid message name." as in
mavlink2rest). Nothing here touches a socket or a clock.

**Fields pymavlink's dialect lacks.** mavlink2rest reads and writes the current MAVLink
definition; pymavlink's generated ardupilotmega is older and lacks the extension fields listed
in EXTENSIONS (compared with mavlink/mavlink's message_definitions for issue 27: Cockpit's
TIMESYNC carries `target_system` and `target_component`). They are accepted with the same checks
as the other fields and carried on the wire: the message is packed with their bytes appended to
its payload (MAVLink 2 extension fields follow the base fields; CRC_EXTRA does not cover them;
a MAVLink 1 frame drops them, as the protocol does).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from functools import cache

from pymavlink.dialects.v20 import ardupilotmega as M

INT_RANGES = {
    "uint8_t": (0, 0xFF), "int8_t": (-0x80, 0x7F), "uint16_t": (0, 0xFFFF), "int16_t": (-0x8000, 0x7FFF),
    "uint32_t": (0, 0xFFFF_FFFF), "int32_t": (-0x8000_0000, 0x7FFF_FFFF),
    "uint64_t": (0, 0xFFFF_FFFF_FFFF_FFFF), "int64_t": (-0x8000_0000_0000_0000, 0x7FFF_FFFF_FFFF_FFFF),
    "uint8_t_mavlink_version": (0, 0xFF), "char": (0, 0xFF),
}
FLOAT32_MAX = 3.4028234663852886e38
TEMPLATE_HEADER = {"system_id": 255, "component_id": 0, "sequence": 0}  # mavlink2rest's MavHeader::default()
NUL = "\u0000"


class BadMessage(ValueError):
    """The client's JSON is not a message gcsd can send (400, or 422 for a wrong type)."""


class UnknownMessage(BadMessage):
    """No message of that name in the dialect (404)."""


@dataclass(frozen=True, slots=True)
class FieldSpec:
    name: str  # pymavlink's
    json_name: str  # mavlink2rest's: "mavtype" for "type"
    kind: str  # "enum", "bits", "chars", "ints", "floats", "int", "float"
    base: str  # the C type of one element
    length: int  # array length; 0 for a scalar
    enum: str | None


@dataclass(frozen=True, slots=True)
class MessageSpec:
    name: str
    cls: type
    fields: tuple[FieldSpec, ...]  # wire order, as written
    by_json: dict  # json_name -> FieldSpec
    arg_order: tuple[str, ...]  # the constructor's order (pymavlink `fieldnames`)


def _bitmask_enums() -> frozenset[str]:
    names = {name for name, entries in M.enums.items() if getattr(entries, "bitmask", False)}
    for cls in M.mavlink_map.values():
        for field, display in getattr(cls, "fielddisplays_by_name", {}).items():
            enum = cls.fieldenums_by_name.get(field)
            if display == "bitmask" and enum:
                names.add(enum)
    return frozenset(names)


BITMASK_ENUMS = _bitmask_enums()
BY_NAME = {cls.msgname: cls for cls in M.mavlink_map.values()}


@cache
def spec_of(cls: type) -> MessageSpec:
    types = dict(zip(cls.fieldnames, cls.fieldtypes))
    lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths))
    enums = cls.fieldenums_by_name
    fields = []
    for name in cls.ordered_fieldnames:
        base, length, enum = types[name], lengths[name], enums.get(name)
        if enum is not None and enum not in M.enums:
            enum = None
        if base == "char" and length:
            kind = "chars"
        elif length:
            kind = "floats" if base in ("float", "double") else "ints"
        elif enum is not None:
            kind = "bits" if enum in BITMASK_ENUMS else "enum"
        else:
            kind = "float" if base in ("float", "double") else "int"
        fields.append(FieldSpec(name, "mavtype" if name == "type" else name, kind, base, length, enum))
    return MessageSpec(cls.msgname, cls, tuple(fields), {f.json_name: f for f in fields}, tuple(cls.fieldnames))


def spec_by_name(name: object) -> MessageSpec:
    cls = BY_NAME.get(name) if isinstance(name, str) else None
    if cls is None:
        raise UnknownMessage("Invalid message name.")
    return spec_of(cls)


@cache
def _entry_names(enum: str) -> dict[int, str]:
    return {value: e.name for value, e in M.enums[enum].items() if not e.name.endswith("_ENUM_END")}


@cache
def _entry_values(enum: str) -> dict[str, int]:
    return {name: value for value, name in _entry_names(enum).items()}


# --- writing ---------------------------------------------------------------------------------

def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


def message_json(msg) -> dict:
    """One pymavlink message as mavlink2rest writes it."""
    out: dict = {"type": msg.get_type()}
    for f in spec_of(type(msg)).fields:
        value = getattr(msg, f.name)
        kind = f.kind
        if kind == "int":
            out[f.json_name] = value
        elif kind == "float":
            out[f.json_name] = value if math.isfinite(value) else None
        elif kind == "enum":
            name = _entry_names(f.enum).get(value)
            out[f.json_name] = value if name is None else {"type": name}
        elif kind == "bits":
            out[f.json_name] = {"bits": value}
        elif kind == "chars":
            text = value.decode("latin-1") if isinstance(value, bytes) else str(value)
            chars = list(text[: f.length])
            out[f.json_name] = chars + [NUL] * (f.length - len(chars))
        elif kind == "floats":
            out[f.json_name] = [_finite(v) for v in value]
        else:
            out[f.json_name] = list(value)
    return out


def template(name: object) -> dict:
    """`GET /v1/helper/mavlink?name=NAME`: a default message under mavlink2rest's default header
    (enums at their first entry, as rust-mavlink's `DEFAULT`)."""
    spec = spec_by_name(name)
    message: dict = {"type": spec.name}
    for f in spec.fields:
        if f.kind == "enum":
            first = next(iter(_entry_names(f.enum).values()), None)
            message[f.json_name] = {"type": first} if first is not None else 0
        elif f.kind == "bits":
            message[f.json_name] = {"bits": 0}
        elif f.kind == "chars":
            message[f.json_name] = [NUL] * f.length
        elif f.kind in ("ints", "floats"):
            message[f.json_name] = [0.0 if f.kind == "floats" else 0] * f.length
        else:
            message[f.json_name] = 0.0 if f.kind == "float" else 0
    return {"header": dict(TEMPLATE_HEADER), "message": message}


# --- reading ---------------------------------------------------------------------------------

@dataclass(frozen=True, slots=True)
class Header:
    system_id: int
    component_id: int
    sequence: int


def parse_envelope(document: object):
    """`{"header": {...}, "message": {...}}` -> (Header, pymavlink message)."""
    if not isinstance(document, dict):
        raise BadMessage("expected an object with 'header' and 'message'")
    unknown = set(document) - {"header", "message"}
    if unknown:
        raise BadMessage(f"unknown key {min(unknown)!r} (expected 'header' and 'message')")
    header = parse_header(document.get("header"))
    return header, parse_message(document.get("message"))


def parse_header(header: object) -> Header:
    if not isinstance(header, dict):
        raise BadMessage("'header' must be an object with system_id, component_id and sequence")
    values = []
    for key in ("system_id", "component_id", "sequence"):
        value = header.get(key, 0 if key == "sequence" else None)
        if value is None:
            raise BadMessage(f"header.{key} is missing")
        values.append(_int(value, "uint8_t", f"header.{key}"))
    unknown = set(header) - {"system_id", "component_id", "sequence"}
    if unknown:
        raise BadMessage(f"header: unknown key {min(unknown)!r}")
    return Header(*values)


# message -> its extension fields of current MAVLink that pymavlink's dialect lacks, in wire
# order: (name, struct code, C type, array length)
EXTENSIONS: dict[str, tuple[tuple[str, str, str, int], ...]] = {
    "TIMESYNC": (("target_system", "B", "uint8_t", 0), ("target_component", "B", "uint8_t", 0)),
    "SERIAL_CONTROL": (("target_system", "B", "uint8_t", 0), ("target_component", "B", "uint8_t", 0)),
    "MISSION_CURRENT": (("mission_id", "I", "uint32_t", 0), ("fence_id", "I", "uint32_t", 0),
                        ("rally_points_id", "I", "uint32_t", 0)),
    "MISSION_COUNT": (("opaque_id", "I", "uint32_t", 0),),
    "MISSION_ACK": (("opaque_id", "I", "uint32_t", 0),),
    "SET_ATTITUDE_TARGET": (("thrust_body", "f", "float", 3),),
    "WIFI_CONFIG_AP": (("mode", "b", "int8_t", 0), ("response", "b", "int8_t", 0)),
}


def parse_message(message: object):
    """A message object (mavlink2rest's forms, see the module docstring) -> pymavlink message."""
    if not isinstance(message, dict):
        raise BadMessage("'message' must be an object with a 'type'")
    spec = spec_by_name(message.get("type"))
    extensions = {e[0]: e for e in EXTENSIONS.get(spec.name, ())}
    for key in message:
        if key != "type" and key not in spec.by_json and key not in extensions:
            raise BadMessage(f"{spec.name} has no field {key!r}")
    values = {}
    for f in spec.fields:
        raw = message.get(f.json_name)
        where = f"{spec.name}.{f.json_name}"
        values[f.name] = _default(f) if raw is None else _value(f, raw, where)
    msg = spec.cls(*(values[name] for name in spec.arg_order))
    if extensions:
        msg = _with_extensions(msg, spec.name, message)
    return msg


def _with_extensions(msg, name: str, message: dict):
    """`msg` carrying the EXTENSIONS fields `message` gives (0 for those it leaves out)."""
    parts, codes = [], ""
    for field, code, base, length in EXTENSIONS[name]:
        raw = message.get(field)
        where = f"{name}.{field}"
        if length:
            f = FieldSpec(field, field, "floats" if code == "f" else "ints", base, length, None)
            value = _default(f) if raw is None else _value(f, raw, where)
            parts += list(value)
        else:
            kind = "float" if code == "f" else "int"
            value = 0 if raw is None else _value(FieldSpec(field, field, kind, base, 0, None), raw, where)
            parts.append(value)
        setattr(msg, field, value)
        codes += f"{length or ''}{code}"
    msg.__class__ = _extended_class(type(msg))
    msg._gcsd_extension_bytes = struct.pack("<" + codes, *parts)
    return msg


@cache
def _extended_class(cls: type) -> type:
    """`cls` whose pack() appends the message's extension bytes to the payload pymavlink packs."""

    def pack(self, mav, force_mavlink1: bool = False) -> bytes:
        if force_mavlink1:
            return cls.pack(self, mav, force_mavlink1=True)
        inner = self._pack

        def with_extensions(mav_, crc_extra, payload, force_mavlink1=False):
            return inner(mav_, crc_extra, payload + self._gcsd_extension_bytes, force_mavlink1=force_mavlink1)

        self._pack = with_extensions
        try:
            return cls.pack(self, mav)
        finally:
            del self._pack

    return type(cls.__name__, (cls,), {"pack": pack})


def _default(f: FieldSpec):
    if f.kind == "chars":
        return b""
    if f.length:
        return [0.0 if f.kind == "floats" else 0] * f.length
    return 0.0 if f.kind == "float" else 0


def _value(f: FieldSpec, raw: object, where: str):
    kind = f.kind
    if kind == "int":
        return _int(raw, f.base, where)
    if kind == "float":
        return _float(raw, where)
    if kind == "enum":
        return _enum(f, raw, where)
    if kind == "bits":
        return _bits(f, raw, where)
    if kind == "chars":
        return _chars(f, raw, where)
    if not isinstance(raw, list) or len(raw) > f.length:
        raise BadMessage(f"{where}: expected a list of at most {f.length} numbers")
    parse = _float if kind == "floats" else (lambda v, w: _int(v, f.base, w))
    items = [parse(v, f"{where}[{i}]") for i, v in enumerate(raw)]
    return items + [0.0 if kind == "floats" else 0] * (f.length - len(items))


def _int(raw: object, base: str, where: str) -> int:
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        raise BadMessage(f"{where}: expected an integer, got {type(raw).__name__}")
    if isinstance(raw, float):
        if not raw.is_integer():
            raise BadMessage(f"{where}: expected an integer, got {raw}")
        raw = int(raw)
    low, high = INT_RANGES[base]
    if not low <= raw <= high:
        raise BadMessage(f"{where}: {raw} is out of range for {base} ({low}..{high})")
    return raw


def _float(raw: object, where: str) -> float:
    if isinstance(raw, bool) or not isinstance(raw, (int, float)):
        raise BadMessage(f"{where}: expected a number, got {type(raw).__name__}")
    value = float(raw)
    if not math.isfinite(value) or abs(value) > FLOAT32_MAX:
        raise BadMessage(f"{where}: {raw} is not a finite float32")
    return value


def _unwrap(raw: object, key: str, where: str, shape: str) -> object:
    """mavlink2rest's wrapped form ({"type": NAME}, {"bits": N}) -> its content; other forms as they are."""
    if isinstance(raw, dict):
        if set(raw) != {key}:
            raise BadMessage(f"{where}: expected {shape}")
        return raw[key]
    return raw


def _enum(f: FieldSpec, raw: object, where: str) -> int:
    raw = _unwrap(raw, "type", where, f'{{"type": "{f.enum}_..."}}')
    if isinstance(raw, str):
        value = _entry_values(f.enum).get(raw)
        if value is None:
            raise BadMessage(f"{where}: {raw!r} is not an entry of {f.enum}")
        raw = value
    return _int(raw, f.base, where)


def _bits(f: FieldSpec, raw: object, where: str) -> int:
    raw = _unwrap(raw, "bits", where, '{"bits": N}')
    if isinstance(raw, str):
        values = _entry_values(f.enum)
        total = 0
        for flag in (part.strip() for part in raw.split("|")):
            if flag and flag not in values:
                raise BadMessage(f"{where}: {flag!r} is not a flag of {f.enum}")
            total |= values.get(flag, 0)
        raw = total
    return _int(raw, f.base, where)


def _chars(f: FieldSpec, raw: object, where: str) -> bytes:
    if isinstance(raw, list):
        parts = []
        for i, c in enumerate(raw):
            if isinstance(c, str) and len(c) == 1:
                parts.append(c)
            elif isinstance(c, int) and not isinstance(c, bool) and 0 <= c <= 0xFF:
                parts.append(chr(c))
            else:
                raise BadMessage(f"{where}[{i}]: expected one character or a byte value")
        raw = "".join(parts)
    if not isinstance(raw, str):
        raise BadMessage(f"{where}: expected a string or a list of characters")
    data = raw.rstrip(NUL).encode("utf-8")
    if len(data) > f.length:
        raise BadMessage(f"{where}: {len(data)} bytes, at most {f.length}")
    return data
