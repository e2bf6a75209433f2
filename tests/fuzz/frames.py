"""What the fuzz suite sends: every command of the dialect with zeros, NaN and seeded wild values,
and every message id with a seeded random payload, as valid MAVLink2 frames.

Commands go out as COMMAND_LONG and COMMAND_INT through pymavlink's own encoder. A random-payload
frame is built by hand: the message's full payload length of random bytes (so its floats are any
bit pattern: NaN with payloads, infinities, denormals, huge values), the target_system /
target_component fields (where the message has them) set to the vehicle so the message is
handled rather than ignored as addressed elsewhere, and the right CRC (X.25 with the message's
CRC_EXTRA): the daemon parses it as a good frame and hands it to whatever handles that id. Some
of the classic ids (below 256) go as MAVLink1 frames with their payload cut short.
"""

from __future__ import annotations

import math
import random
import re
import struct
from collections.abc import Iterator
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as M

SOURCE = (255, 190)  # the ground station's (sysid, compid): MAV_GCS_SYSID's default
FLOAT_MAX = 3.4028234663852886e38
DENORMAL = 1e-45


@dataclass(frozen=True)
class Chunk:
    """A group of frames sent back to back, then the daemon must still answer; `name` says what they were."""

    name: str
    frames: tuple[bytes, ...]


def wild_float(rng: random.Random) -> float:
    """One value from the edges of float32: infinities, NaN, huge, tiny, negative, denormal, plain."""
    return rng.choice((
        math.inf, -math.inf, math.nan, FLOAT_MAX, -FLOAT_MAX, 1e30, -1e30, DENORMAL, -DENORMAL, 0.0, -0.0,
        -1.0, 1.0, 2.0, 65535.0, 65536.0, 2.0**31, -2.0**31, 21196.0, 1e7, -1e7,
        rng.uniform(-1e6, 1e6), rng.uniform(-1.0, 1.0), float(rng.randint(-10, 300)),
    ))


def wild_int32(rng: random.Random) -> int:
    return rng.choice((0, 1, -1, 2**31 - 1, -2**31, 900_000_001, -1_800_000_001, rng.randint(-2**31, 2**31 - 1)))


def _f32(value: float) -> float:
    """What a float32 field can carry (the encoder packs with struct 'f')."""
    return struct.unpack("<f", struct.pack("<f", value))[0]


def command_frames(mav, command: int, target: tuple[int, int], rng: random.Random, wild_rounds: int) -> list[bytes]:
    """COMMAND_LONG and COMMAND_INT for one command: all zeros, all NaN, then `wild_rounds` wild sets."""
    sets = [([0.0] * 7, 0, 0), ([math.nan] * 7, 0, 0)]  # COMMAND_INT's x/y are integers: 0 in both
    sets += [([wild_float(rng) for _ in range(7)], wild_int32(rng), wild_int32(rng)) for _ in range(wild_rounds)]
    frames = []
    for params, x, y in sets:
        p = [_f32(v) for v in params]
        frames.append(bytes(M.MAVLink_command_long_message(*target, command, 0, *p).pack(mav)))
        frame = rng.choice((M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_FRAME_GLOBAL_INT,
                            M.MAV_FRAME_LOCAL_NED, rng.randrange(256)))
        frames.append(bytes(M.MAVLink_command_int_message(*target, frame, command, 0, 0, p[0], p[1], p[2], p[3],
                                                          x, y, p[6]).pack(mav)))
    return frames


def command_chunks(target: tuple[int, int], seed: int, wild_rounds: int) -> Iterator[Chunk]:
    """One chunk per MAV_CMD of the dialect (in id order), plus unknown ids at the ends of uint16."""
    rng = random.Random(seed)
    mav = M.MAVLink(None, srcSystem=SOURCE[0], srcComponent=SOURCE[1])
    commands = sorted(M.enums["MAV_CMD"])
    commands = [c for c in commands if c != M.MAV_CMD_ENUM_END] + [0, 65535]
    for command in commands:
        entry = M.enums["MAV_CMD"].get(command)
        name = entry.name if entry is not None else f"unknown command {command}"
        yield Chunk(name, tuple(command_frames(mav, command, target, rng, wild_rounds)))


_FIELD_CODE = re.compile(r"(\d*)([a-zA-Z])")


def field_layout(cls) -> dict[str, tuple[int, str]]:
    """Wire offset and struct code of each field of a message class (wire order)."""
    codes = _FIELD_CODE.findall(cls.unpacker.format[1:])
    assert len(codes) == len(cls.ordered_fieldnames), cls.msgname
    layout, offset = {}, 0
    for name, (count, code) in zip(cls.ordered_fieldnames, codes, strict=True):
        fmt = f"<{count}{code}"
        layout[name] = (offset, fmt)
        offset += struct.calcsize(fmt)
    return layout


def payload_length(cls) -> int:
    return struct.calcsize(cls.unpacker.format)


def random_frame(cls, rng: random.Random, seq: int, target: tuple[int, int] | None, version: int = 2) -> bytes:
    """A frame of message `cls` with a random payload and a valid CRC. MAVLink2: the full payload;
    MAVLink1 (ids below 256): a payload cut anywhere from none to all of it (a receiver fills
    what is missing with zeros, extensions included)."""
    full = payload_length(cls)
    payload = bytearray(rng.randbytes(full if version == 2 else rng.randint(0, full)))
    if target is not None:
        layout = field_layout(cls)
        for field, value in (("target_system", target[0]), ("target_component", target[1])):
            if field in layout:
                offset, fmt = layout[field]
                if offset + struct.calcsize(fmt) <= len(payload):
                    struct.pack_into(fmt, payload, offset, value)
    msgid = cls.id
    if version == 1:
        header = bytes([0xFE, len(payload), seq & 0xFF, *SOURCE, msgid])
    else:
        header = bytes([0xFD, len(payload), 0, 0, seq & 0xFF, *SOURCE, msgid & 0xFF, (msgid >> 8) & 0xFF,
                        msgid >> 16])
    crc = M.x25crc(header[1:] + bytes(payload))
    crc.accumulate(bytes([cls.crc_extra]))
    return header + bytes(payload) + struct.pack("<H", crc.crc)


def message_chunks(target: tuple[int, int], seed: int, copies: int) -> Iterator[Chunk]:
    """One chunk per message id of the dialect: `copies` random payloads, most of them addressed to
    us, one in four of those with an id below 256 as MAVLink1."""
    rng = random.Random(seed)
    seq = 0
    for msgid in sorted(M.mavlink_map):
        cls = M.mavlink_map[msgid]
        frames = []
        for n in range(copies):
            version = 1 if msgid < 256 and n % 4 == 2 else 2  # one in four of the classic ids as MAVLink1
            frames.append(random_frame(cls, rng, seq, target if n % 4 != 3 else None, version))
            seq += 1
        yield Chunk(f"{cls.msgname} (id {msgid})", tuple(frames))


NAV_COMMANDS = (
    M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_LOITER_UNLIM, M.MAV_CMD_NAV_LOITER_TURNS, M.MAV_CMD_NAV_LOITER_TIME,
    M.MAV_CMD_NAV_RETURN_TO_LAUNCH, M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_LOITER_TO_ALT,
    M.MAV_CMD_NAV_SPLINE_WAYPOINT, M.MAV_CMD_NAV_DELAY, M.MAV_CMD_CONDITION_DELAY, M.MAV_CMD_CONDITION_DISTANCE,
    M.MAV_CMD_CONDITION_YAW, M.MAV_CMD_DO_JUMP, M.MAV_CMD_DO_CHANGE_SPEED, M.MAV_CMD_DO_SET_HOME,
    M.MAV_CMD_DO_SET_SERVO, M.MAV_CMD_DO_REPEAT_SERVO, M.MAV_CMD_DO_SET_RELAY, M.MAV_CMD_DO_REPEAT_RELAY,
    M.MAV_CMD_DO_SET_ROI, M.MAV_CMD_DO_SET_ROI_LOCATION, M.MAV_CMD_DO_FENCE_ENABLE, M.MAV_CMD_DO_LAND_START,
    M.MAV_CMD_JUMP_TAG, M.MAV_CMD_DO_JUMP_TAG, M.MAV_CMD_NAV_VTOL_TAKEOFF, M.MAV_CMD_NAV_VTOL_LAND,
)
FENCE_COMMANDS = (
    M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION,
    M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, M.MAV_CMD_NAV_FENCE_RETURN_POINT,
)
PLAN_FRAMES = (M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_FRAME_GLOBAL_INT,
               M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, M.MAV_FRAME_MISSION)


def _plan_value(rng: random.Random, finite: bool) -> float:
    """A parameter: wild; when `finite`, wild but a number (huge, negative, tiny), so the plan may be kept."""
    while True:
        value = _f32(wild_float(rng))
        if not finite or math.isfinite(value):
            return value


def random_plan(rng: random.Random, mission_type: int, home_e7: tuple[int, int], length: int) -> list:
    """MISSION_ITEM_INT messages (seq set at upload) for one plan: half of the plans use only finite
    values (so some are accepted and then flown, extreme as they are), half anything at all."""
    finite = rng.random() < 0.5
    commands = {M.MAV_MISSION_TYPE_MISSION: NAV_COMMANDS, M.MAV_MISSION_TYPE_FENCE: FENCE_COMMANDS,
                M.MAV_MISSION_TYPE_RALLY: (M.MAV_CMD_NAV_RALLY_POINT,)}[mission_type]
    items = []
    for _ in range(length):
        near = rng.random() < 0.7
        x = home_e7[0] + rng.randint(-20_000, 20_000) if near else wild_int32(rng)
        y = home_e7[1] + rng.randint(-20_000, 20_000) if near else wild_int32(rng)
        command = rng.choice(commands) if rng.random() < 0.9 else rng.choice(sorted(M.enums["MAV_CMD"]))
        frame = rng.choice(PLAN_FRAMES) if rng.random() < 0.9 else rng.randrange(256)
        params = [_plan_value(rng, finite) for _ in range(5)]
        items.append(M.MAVLink_mission_item_int_message(
            1, 1, 0, frame, command, 0, 1, *params[:4], x, y, params[4], mission_type))
    return items


# parameters that change who the vehicle or its ground station is: a legitimate effect that would
# only make the ground station of the test a stranger (its requests then go unanswered by design)
IDENTITY_PARAMS = frozenset({"SYSID_THISMAV", "MAV_SYSID", "SYSID_MYGCS", "MAV_GCS_SYSID", "SYSID_ENFORCE"})
PARAM_TYPES = (M.MAV_PARAM_TYPE_UINT8, M.MAV_PARAM_TYPE_INT8, M.MAV_PARAM_TYPE_INT16, M.MAV_PARAM_TYPE_INT32,
               M.MAV_PARAM_TYPE_REAL32)


def param_chunks(names: list[str], target: tuple[int, int], seed: int, copies: int) -> Iterator[Chunk]:
    """PARAM_SET of every parameter (but the identity ones) with wild values, 20 parameters a chunk."""
    rng = random.Random(seed)
    mav = M.MAVLink(None, srcSystem=SOURCE[0], srcComponent=SOURCE[1])
    names = [n for n in names if n not in IDENTITY_PARAMS]
    for start in range(0, len(names), 20):
        frames = []
        for name in names[start:start + 20]:
            for _ in range(copies):
                value = _f32(wild_float(rng))
                frames.append(bytes(M.MAVLink_param_set_message(*target, name.encode(), value,
                                                                 rng.choice(PARAM_TYPES)).pack(mav)))
                mav.seq = (mav.seq + 1) % 256
        yield Chunk(f"PARAM_SET {names[start]}..{names[min(start + 19, len(names) - 1)]}", tuple(frames))
