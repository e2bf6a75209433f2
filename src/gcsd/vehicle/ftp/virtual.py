"""Virtual files under `@PARAM/` and `@MISSION/`, served from the same stores the message
protocols use (REFERENCE.md 6.1, 7.5, 8: "virtual roots").

A path is virtual when, after at most one leading "/", it starts with "@". Names:

- `@PARAM/param.pck[?start=N&count=C&withdefaults=0|1]`: read, a snapshot of the parameters
  taken at open; write, a param.pck upload applied when the session is terminated. At most 4
  opens at once (ENFILE beyond). Opening it for reading calls `on_param_download` (the banner,
  as ArduPilot sends it). Its size at open is exact for 239-byte reads (MAVSDK ends a burst on
  the size it was told); a handle then serves the read size of its first read for its whole
  life: another size is EINVAL (the padding depends on it), except a read that reaches the end
  of the file (a client's short last read), which is served.
- `@MISSION/mission.dat|fence.dat|rally.dat`: see mission_files.py.
- Any other `@` name is FileNotFound. The virtual files and directories cannot be removed,
  renamed, truncated or made into directories (FileProtected).

Handles share one small interface with fs.RealFile: `size`, `writable`, `read(offset, count)`,
`write(offset, data)`, `close()` (may raise FtpError: the answer to TerminateSession) and
`abort()` (a reset or an idle timeout: an unfinished upload is dropped, nothing is applied).
"""

from __future__ import annotations

import errno
from collections.abc import Callable, Iterable
from typing import Protocol

from gcsd.vehicle.ftp.fs import DirEntry
from gcsd.vehicle.ftp.parampck import (
    MAX_UPLOAD_BYTES,
    ParamLike,
    PckQuery,
    decode_upload,
    encode,
    parse_query,
)
from gcsd.vehicle.ftp.protocol import DATA_MAX, FtpError, Nak
from gcsd.vehicle.ftp.upload import BufferedUpload

PARAM_DIR, PARAM_FILE = "@PARAM", "param.pck"
MISSION_DIR = "@MISSION"
MAX_PARAM_OPENS = 4


class Handle(Protocol):
    size: int
    writable: bool

    def read(self, offset: int, count: int) -> bytes: ...
    def write(self, offset: int, data: bytes) -> None: ...
    def close(self) -> None: ...
    def abort(self) -> None: ...


class ParamSource(Protocol):
    """What the parameter service offers the FTP server."""

    def entries(self) -> Iterable[ParamLike]: ...
    def count(self) -> int: ...
    def set_from_file(self, name: str, value: float) -> bool: ...
    def commit(self) -> None: ...  # save once after an upload was applied
    def downloaded(self) -> None: ...  # a param.pck download started (the banner)


def split_virtual(raw: bytes) -> tuple[str, str] | None:
    """("@ROOT", "rest") for a virtual path, else None."""
    text = raw.decode("utf-8", "surrogateescape")
    text = text.removeprefix("/")
    if not text.startswith("@"):
        return None
    root, _, rest = text.partition("/")
    return root, rest.rstrip("/")


class ParamPckReader:
    writable = False

    def __init__(self, params: list[ParamLike], query: PckQuery, release: Callable[[], None]) -> None:
        self._params = params
        self._query = query
        self._release = release
        self._content = encode(params, len(params), query, DATA_MAX)
        self.size = len(self._content)
        self._block: int | None = None

    def read(self, offset: int, count: int) -> bytes:
        count = min(count, DATA_MAX)
        if count <= 0:
            return b""
        if self._block is None:
            self._block = count
            if count != DATA_MAX:
                self._content = encode(self._params, len(self._params), self._query, count)
        elif count != self._block and offset + count < len(self._content):
            raise FtpError(Nak.FAIL_ERRNO, errno.EINVAL)
        return self._content[offset:offset + count]

    def write(self, offset: int, data: bytes) -> None:
        raise FtpError(Nak.FAIL)

    def close(self) -> None:
        self._release()

    abort = close


class ParamPckWriter(BufferedUpload):
    max_bytes = MAX_UPLOAD_BYTES
    too_big_errno = errno.EINVAL

    def __init__(self, source: ParamSource, release: Callable[[], None]) -> None:
        super().__init__(release)
        self._source = source

    def apply(self, data: bytes) -> None:
        params = decode_upload(data)
        if params is None:
            raise FtpError(Nak.FAIL_ERRNO, errno.EINVAL)
        for p in params:
            self._source.set_from_file(p.name, p.value)
        self._source.commit()


class VirtualFiles:
    def __init__(self, params: ParamSource | None = None, missions=None) -> None:
        self.params = params
        self.missions = missions  # mission_files.MissionFiles, or None
        self._param_opens = 0

    def _param_query(self, rest: str) -> PckQuery:
        name, _sep, query = rest.partition("?")
        if self.params is None or name != PARAM_FILE:
            raise FtpError(Nak.FILE_NOT_FOUND)
        parsed = parse_query(query)
        if parsed is None:
            raise FtpError(Nak.FAIL_ERRNO, errno.EINVAL)
        if self._param_opens >= MAX_PARAM_OPENS:
            raise FtpError(Nak.FAIL_ERRNO, errno.ENFILE)
        return parsed

    def _release_param(self) -> None:
        self._param_opens = max(0, self._param_opens - 1)

    def open_read(self, root: str, rest: str, announce: bool = True) -> Handle:
        """Open for reading; `announce` (an OpenFileRO, not a CRC) tells the parameter service."""
        if root == PARAM_DIR:
            query = self._param_query(rest)
            params = list(self.params.entries())
            if query.start and query.start >= len(params):
                raise FtpError(Nak.FAIL_ERRNO, errno.EINVAL)
            self._param_opens += 1
            reader = ParamPckReader(params, query, self._release_param)
            if announce:
                self.params.downloaded()
            return reader
        if root == MISSION_DIR and self.missions is not None:
            return self.missions.open_read(rest)
        raise FtpError(Nak.FILE_NOT_FOUND)

    def open_write(self, root: str, rest: str) -> Handle:
        if root == PARAM_DIR:
            self._param_query(rest)
            self._param_opens += 1
            return ParamPckWriter(self.params, self._release_param)
        if root == MISSION_DIR and self.missions is not None:
            return self.missions.open_write(rest)
        raise FtpError(Nak.FILE_NOT_FOUND)

    def list_dir(self, root: str, rest: str) -> list[DirEntry]:
        if rest:
            raise FtpError(Nak.FILE_NOT_FOUND)
        if root == PARAM_DIR and self.params is not None:
            return [DirEntry(PARAM_FILE, False, self.params.count() * 12)]  # ArduPilot's estimate
        if root == MISSION_DIR and self.missions is not None:
            return self.missions.list_dir()
        raise FtpError(Nak.FILE_NOT_FOUND)

    def exists(self, root: str, rest: str) -> bool:
        """A virtual directory or file that is served here (its query aside)."""
        if root == PARAM_DIR and self.params is not None:
            return rest in ("", PARAM_FILE) or rest.startswith(PARAM_FILE + "?")
        if root == MISSION_DIR and self.missions is not None:
            return rest == "" or rest in self.missions.names()
        return False

    def root_entries(self) -> list[DirEntry]:
        """The virtual directories, listed after the real entries of "/"."""
        out = []
        if self.params is not None:
            out.append(DirEntry(PARAM_DIR, True, 0))
        if self.missions is not None:
            out.append(DirEntry(MISSION_DIR, True, 0))
        return out
