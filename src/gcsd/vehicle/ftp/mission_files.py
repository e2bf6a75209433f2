"""`@MISSION/mission.dat`, `fence.dat`, `rally.dat` (AP_Filesystem_Mission.cpp; REFERENCE.md 7.5).

Layout, little-endian: a 10-byte header (u16 magic 0x763d, u16 mission_type, u16 options,
u16 start, u16 num_items), then num_items MISSION_ITEM_INT payloads packed in wire order, full
length (38 bytes: param1..4, x, y, z, seq, command, target_system, target_component, frame,
current, autocontinue, mission_type), which is how MAVProxy's `wp|fence|rally ftp` and
`ftpload` read and write them.

Reading serves a snapshot of the plan taken at open, as a download serves it (mission item 0
is home), with seq = index and target 0/0; its size at open is exact (ArduPilot reports a fake
1 MiB). Writing buffers the file; when the session ends (TerminateSession) it is checked and
handed to the mission service, which applies the same checks as an upload over messages and
replaces the plan atomically: the answer is ACK, or FailErrno EINVAL for a malformed file
(bad magic, wrong type, a count that is not the length, an all-zero item: the client did not
fill the file) or a plan the service refuses (old plan kept). gcsd improvement: only whole
plans (options 0, start 0); ArduPilot's partial mission update (options NO_CLEAR, start) is
EINVAL here. One upload per file at a time (EBUSY); an upload abandoned until the session's
idle timeout changes nothing.
"""

from __future__ import annotations

import errno
import struct
from collections.abc import Callable
from typing import Protocol

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.ftp.fs import DirEntry
from gcsd.vehicle.ftp.protocol import FtpError, Nak
from gcsd.vehicle.ftp.upload import BufferedUpload
from gcsd.vehicle.mission.items import MissionItem

MAGIC = 0x763D
HEADER = struct.Struct("<HHHHH")
ITEM = struct.Struct("<ffffiifHHBBBBBB")  # MISSION_ITEM_INT, wire order
FILES = {"mission.dat": M.MAV_MISSION_TYPE_MISSION, "fence.dat": M.MAV_MISSION_TYPE_FENCE,
         "rally.dat": M.MAV_MISSION_TYPE_RALLY}
MAX_ITEMS = 0xFFFF


class PlanSource(Protocol):
    """What the mission service offers: whole plans, read and written through its stores."""

    def read_plan(self, mission_type: int) -> tuple[MissionItem, ...] | None: ...
    def write_plan(self, mission_type: int, items: list[MissionItem]) -> int: ...  # MAV_MISSION_RESULT


def encode_plan(mission_type: int, items) -> bytes:
    out = bytearray(HEADER.pack(MAGIC, mission_type, 0, 0, len(items)))
    for seq, it in enumerate(items):
        out += ITEM.pack(it.param1, it.param2, it.param3, it.param4, it.x, it.y, it.z, seq, it.command,
                         0, 0, it.frame, it.current, it.autocontinue, mission_type)
    return bytes(out)


def decode_plan(data: bytes, mission_type: int) -> list[MissionItem] | None:
    """The items of an uploaded file, or None when it is malformed."""
    if len(data) < HEADER.size:
        return None
    magic, dtype, options, start, count = HEADER.unpack_from(data)
    if magic != MAGIC or dtype != mission_type or options or start:
        return None
    if len(data) - HEADER.size != count * ITEM.size:
        return None
    items = []
    for i in range(count):
        raw = data[HEADER.size + i * ITEM.size:HEADER.size + (i + 1) * ITEM.size]
        if not any(raw):
            return None
        p1, p2, p3, p4, x, y, z, _seq, command, _ts, _tc, frame, current, autocontinue, _mt = ITEM.unpack(raw)
        items.append(MissionItem(command, frame, current, autocontinue, p1, p2, p3, p4, x, y, z))
    return items


class PlanReader:
    writable = False

    def __init__(self, content: bytes) -> None:
        self._content = content
        self.size = len(content)

    def read(self, offset: int, count: int) -> bytes:
        return self._content[offset:offset + count]

    def write(self, offset: int, data: bytes) -> None:
        raise FtpError(Nak.FAIL)

    def close(self) -> None:
        pass

    abort = close


class PlanWriter(BufferedUpload):
    max_bytes = HEADER.size + MAX_ITEMS * ITEM.size

    def __init__(self, mission_type: int, source: PlanSource, release: Callable[[], None]) -> None:
        super().__init__(release)
        self._type = mission_type
        self._source = source

    def apply(self, data: bytes) -> None:
        items = decode_plan(data, self._type)
        if items is None or self._source.write_plan(self._type, items) != M.MAV_MISSION_ACCEPTED:
            raise FtpError(Nak.FAIL_ERRNO, errno.EINVAL)


class MissionFiles:
    def __init__(self, source: PlanSource) -> None:
        self.source = source
        self._uploading: set[int] = set()

    def names(self) -> tuple[str, ...]:
        return tuple(FILES)

    def _type(self, name: str) -> int:
        mission_type = FILES.get(name)
        if mission_type is None:
            raise FtpError(Nak.FILE_NOT_FOUND)
        return mission_type

    def _content(self, mission_type: int) -> bytes:
        items = self.source.read_plan(mission_type)
        if items is None:
            raise FtpError(Nak.FILE_NOT_FOUND)
        return encode_plan(mission_type, items)

    def open_read(self, name: str) -> PlanReader:
        return PlanReader(self._content(self._type(name)))

    def open_write(self, name: str) -> PlanWriter:
        mission_type = self._type(name)
        if mission_type in self._uploading:
            raise FtpError(Nak.FAIL_ERRNO, errno.EBUSY)
        self._uploading.add(mission_type)
        return PlanWriter(mission_type, self.source, lambda: self._uploading.discard(mission_type))

    def list_dir(self) -> list[DirEntry]:
        return [DirEntry(name, False, len(self._content(t))) for name, t in FILES.items()]
