"""The FTP filesystem adapter: every path confined to the root, file I/O bounded.

**Confinement.** A client path is bytes. It is decoded (UTF-8, undecodable bytes kept as
surrogates), a NUL or an empty path is refused, a leading "/" is dropped (the root *is* "/"), and
any ".." component is refused outright. The remaining components are joined under the root,
which was resolved once at start, and the result is resolved again with every symlink followed
(`Path.resolve`, non-strict so a file about to be created resolves too). The resolved path must
be the root or lie under it, compared component by component (`Path.is_relative_to` on resolved
paths, never a string prefix, so a root `/data` never admits `/data2`). Anything else raises
FileNotFound, and nothing outside the root is opened, listed, stat'ed, renamed or removed.
**Mounts** (`mounts={"logs": DIR}`): a first component naming a mount is served from that
directory instead (the flight logs, kept beside the FTP root, appear as `logs/`); the same rules
confine a mounted path to its directory (any of the roots), and a mount point itself is listed
in the root, and cannot be removed or renamed.
Operations on a directory entry itself (remove, rename) act on the entry inside its resolved
parent, so a symlink is removed or renamed, never its target; the entry must still resolve
inside the root. The root itself cannot be removed or renamed (Fail). Files are opened with
O_NOFOLLOW on the resolved path, so a symlink swapped in after the check is not followed.
Not covered: hard links made by someone with shell access inside the root (an FTP client
cannot make one).

**Blocking.** The adapter is synchronous by design and every call does bounded work: one
metadata call, one `pread`/`pwrite` of at most 64 KiB, or one directory scan. Local-disk calls
of that size cost microseconds, so the event loop is never held for long; CRC32 of a large file
is computed by the server in 1 MiB slices across send passes. (A network filesystem as the FTP
root would block the loop for its round trips: keep the root local.)

Errors: OSError becomes FileNotFound (ENOENT), FileExists (EEXIST) or FailErrno with the errno,
as ArduPilot's GCS_FTP::error maps them.
"""

from __future__ import annotations

import errno
import os
import stat
from dataclasses import dataclass
from pathlib import Path

from gcsd.vehicle.ftp.protocol import FtpError, Nak

READ_CHUNK_MAX = 64 * 1024


def os_error(exc: OSError) -> FtpError:
    code = exc.errno or errno.EIO
    if code == errno.ENOENT:
        return FtpError(Nak.FILE_NOT_FOUND)
    if code == errno.EEXIST:
        return FtpError(Nak.FILE_EXISTS)
    if code == errno.ELOOP:  # O_NOFOLLOW met a symlink: treat as absent
        return FtpError(Nak.FILE_NOT_FOUND)
    return FtpError(Nak.FAIL_ERRNO, code)


@dataclass(frozen=True, slots=True)
class DirEntry:
    name: str
    is_dir: bool
    size: int


class RealFile:
    """An open regular file inside the root: positioned reads and writes, size-limited."""

    def __init__(self, fd: int, writable: bool, max_bytes: int) -> None:
        self.fd = fd
        self.writable = writable
        self.max_bytes = max_bytes
        self.size = os.fstat(fd).st_size

    def read(self, offset: int, count: int) -> bytes:
        try:
            return os.pread(self.fd, min(count, READ_CHUNK_MAX), offset)
        except OSError as exc:
            raise os_error(exc) from None

    def write(self, offset: int, data: bytes) -> None:
        if offset + len(data) > self.max_bytes:
            raise FtpError(Nak.FAIL_ERRNO, errno.EFBIG)
        try:
            os.pwrite(self.fd, data, offset)
        except OSError as exc:
            raise os_error(exc) from None

    def close(self) -> None:
        try:
            os.close(self.fd)
        except OSError as exc:
            raise os_error(exc) from None

    def abort(self) -> None:
        """Close without a protocol answer (session reset, idle timeout)."""
        try:
            os.close(self.fd)
        except OSError:
            pass


class ConfinedFs:
    def __init__(self, root: str | os.PathLike, max_file_bytes: int,
                 mounts: dict[str, str | os.PathLike] | None = None) -> None:
        Path(root).mkdir(parents=True, exist_ok=True)
        self.root = Path(root).resolve(strict=True)
        self.max_file_bytes = max_file_bytes
        self.mounts: dict[str, Path] = {}
        for name, target in (mounts or {}).items():
            Path(target).mkdir(parents=True, exist_ok=True)
            self.mounts[name] = Path(target).resolve(strict=True)
        self._roots = (self.root, *self.mounts.values())

    # --- confinement -----------------------------------------------------------------------
    def _lexical(self, raw: bytes) -> Path:
        if not raw or b"\0" in raw:
            raise FtpError(Nak.FILE_NOT_FOUND)
        text = raw.decode("utf-8", "surrogateescape")
        parts = [p for p in text.split("/") if p not in ("", ".")]
        if ".." in parts:
            raise FtpError(Nak.FILE_NOT_FOUND)
        if parts and parts[0] in self.mounts:
            return self.mounts[parts[0]].joinpath(*parts[1:])
        return self.root.joinpath(*parts)

    def _inside(self, path: Path) -> bool:
        return any(path == root or path.is_relative_to(root) for root in self._roots)

    def resolve(self, raw: bytes) -> Path:
        """The fully resolved path (symlinks followed), which lies inside the root."""
        try:
            resolved = self._lexical(raw).resolve(strict=False)
        except (OSError, RuntimeError):  # symlink loops
            raise FtpError(Nak.FILE_NOT_FOUND) from None
        if not self._inside(resolved):
            raise FtpError(Nak.FILE_NOT_FOUND)
        return resolved

    def entry(self, raw: bytes) -> Path:
        """The directory entry itself (not what a symlink points to): its parent resolved inside
        the root, the entry's own resolution inside the root too, and never the root."""
        lexical = self._lexical(raw)
        if lexical in self._roots:
            raise FtpError(Nak.FAIL)
        self.resolve(raw)
        try:
            parent = lexical.parent.resolve(strict=False)
        except (OSError, RuntimeError):
            raise FtpError(Nak.FILE_NOT_FOUND) from None
        if not self._inside(parent):
            raise FtpError(Nak.FILE_NOT_FOUND)
        return parent / lexical.name

    # --- files -----------------------------------------------------------------------------
    def open_read(self, raw: bytes) -> RealFile:
        return self._open(self.resolve(raw), os.O_RDONLY, writable=False)

    def open_write(self, raw: bytes, truncate: bool) -> RealFile:
        flags = os.O_WRONLY | os.O_CREAT | (os.O_TRUNC if truncate else 0)
        return self._open(self.resolve(raw), flags, writable=True)

    def _open(self, path: Path, flags: int, writable: bool) -> RealFile:
        try:
            fd = os.open(path, flags | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK, 0o644)
        except OSError as exc:
            raise os_error(exc) from None
        try:
            mode = os.fstat(fd).st_mode
            if not stat.S_ISREG(mode):
                raise FtpError(Nak.FAIL_ERRNO, errno.EISDIR if stat.S_ISDIR(mode) else errno.EINVAL)
            return RealFile(fd, writable, self.max_file_bytes)
        except BaseException:
            os.close(fd)
            raise

    def truncate(self, raw: bytes, length: int) -> None:
        if length > self.max_file_bytes:
            raise FtpError(Nak.FAIL_ERRNO, errno.EFBIG)
        f = self._open(self.resolve(raw), os.O_WRONLY, writable=True)
        try:
            os.ftruncate(f.fd, length)
        except OSError as exc:
            raise os_error(exc) from None
        finally:
            f.close()

    # --- directories -----------------------------------------------------------------------
    def list_dir(self, raw: bytes) -> list[DirEntry]:
        """Regular files and directories, sorted by name; entries that resolve outside the root,
        dangling links and special files are left out."""
        path = self.resolve(raw)
        try:
            with os.scandir(path) as it:
                items = sorted(it, key=lambda e: e.name)
        except OSError as exc:
            raise os_error(exc) from None
        out = []
        for item in items:
            try:
                if item.is_symlink():
                    target = Path(item.path).resolve(strict=True)
                    if not self._inside(target):
                        continue
                st = item.stat(follow_symlinks=True)
            except (OSError, RuntimeError):
                continue
            if stat.S_ISDIR(st.st_mode):
                out.append(DirEntry(item.name, True, 0))
            elif stat.S_ISREG(st.st_mode):
                out.append(DirEntry(item.name, False, st.st_size))
        if path == self.root and self.mounts:  # a mount hides a same-named entry of the root
            out = sorted([e for e in out if e.name not in self.mounts]
                         + [DirEntry(name, True, 0) for name in self.mounts], key=lambda e: e.name)
        return out

    def mkdir(self, raw: bytes) -> None:
        self._call(os.mkdir, self.entry(raw))

    def remove_file(self, raw: bytes) -> None:
        path = self.entry(raw)
        try:
            if stat.S_ISDIR(os.lstat(path).st_mode):
                raise FtpError(Nak.FAIL_ERRNO, errno.EISDIR)
        except OSError as exc:
            raise os_error(exc) from None
        self._call(os.unlink, path)

    def remove_dir(self, raw: bytes) -> None:
        self._call(os.rmdir, self.entry(raw))

    def rename(self, old: bytes, new: bytes) -> None:
        src, dst = self.entry(old), self.entry(new)
        try:
            os.rename(src, dst)
        except OSError as exc:
            raise os_error(exc) from None

    @staticmethod
    def _call(fn, path: Path) -> None:
        try:
            fn(path)
        except OSError as exc:
            raise os_error(exc) from None
