"""A write-only virtual file (a param.pck or a mission plan being uploaded): writes at any offset
are gathered in memory, at most `max_bytes` (beyond: NAK FailErrno with `too_big_errno`), and the
whole file is applied by `apply()` when the client closes it. Reads are NAK Fail. `release` is
called on close or abort, so the owner can allow the next upload."""

from __future__ import annotations

import errno
from abc import ABC, abstractmethod
from collections.abc import Callable

from gcsd.vehicle.ftp.protocol import FtpError, Nak


class BufferedUpload(ABC):
    writable = True
    size = 0
    max_bytes: int
    too_big_errno: int = errno.EFBIG

    def __init__(self, release: Callable[[], None]) -> None:
        self._release = release
        self._buf = bytearray()

    def read(self, offset: int, count: int) -> bytes:
        raise FtpError(Nak.FAIL)

    def write(self, offset: int, data: bytes) -> None:
        end = offset + len(data)
        if end > self.max_bytes:
            raise FtpError(Nak.FAIL_ERRNO, self.too_big_errno)
        if end > len(self._buf):
            self._buf.extend(bytes(end - len(self._buf)))
        self._buf[offset:end] = data

    def close(self) -> None:
        self._release()
        self.apply(bytes(self._buf))

    def abort(self) -> None:
        self._release()

    @abstractmethod
    def apply(self, data: bytes) -> None:
        """Use the whole uploaded file; raise FtpError if it cannot be used."""
