"""One daemon per state directory: an exclusive lock on `state_dir/gcsd.lock`, held while it runs.

Two daemons on one state_dir would both write mav.parm, the missions and the signing timestamp,
and the second would unlink and rebind the first one's control socket, so `gcsd status` could
no longer reach the daemon that is serving. So `gcsd run` (app.py) and `gcsd.embed.serve` take
this lock before anything reads or writes state (before the vehicles load their parameters and
count the boot), and a second daemon exits with one clear line naming the directory and the pid
that holds it (exit 1), having changed nothing.

States: unlocked -> held (`acquire`: open or create the file, flock LOCK_EX | LOCK_NB, write our
pid into it for the message a second daemon prints) -> released (`release`, or the process
ends: the kernel drops a flock with its descriptor, so a daemon that was killed never leaves a
stale lock behind and no timeout is needed). The file itself is left in place: removing a lock
file races with a daemon that has just opened it.
"""

from __future__ import annotations

import fcntl
import os
from dataclasses import dataclass
from pathlib import Path

LOCK_NAME = "gcsd.lock"


class StateDirBusy(Exception):
    """Another process holds the state directory."""


@dataclass
class StateLock:
    path: Path
    fd: int

    def release(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)  # closing the descriptor releases the flock
            self.fd = -1


def acquire(state_dir: Path) -> StateLock:
    """Lock `state_dir` (which must exist) for this process; StateDirBusy if another one holds it."""
    path = Path(state_dir) / LOCK_NAME
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o600)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = _holder(fd)
        os.close(fd)
        raise StateDirBusy(
            f"state_dir {Path(state_dir).absolute()} is in use by another gcsd{holder}: stop that one "
            f"first, or give this one a state_dir of its own") from None
    except OSError:
        os.close(fd)
        raise
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    return StateLock(path, fd)


def _holder(fd: int) -> str:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        return ""
    return f" (pid {text})" if text.isdecimal() else ""
