"""Mission, fence and rally files written off the event loop, the upload's answers held until
the plan is durable (MISSION_ACK only after the file is on disk).

The stores save through `save(path, text, store)` before they adopt a plan (mission/stores.py).
Inside a running event loop, for a finished upload (`deferring`), the text is taken on the loop
and the write (gcsd.atomic: temporary file, fsync, rename, fsync of the directory) is handed to
this writer's worker thread; the store adopts the plan in memory as before, and everything the
transfer answered (the ACKs, PlanChanged, texts) is held (`hold`) and released on the loop when
the write is done. A write that fails puts the previous plan back and turns the held answers
into what a failed synchronous save gave: MISSION_ACK ERROR and "<Plan> not saved: <reason>".
Without a running loop (the unit-test harness, a script) and for a clear or an FTP plan write,
`save` writes at once, as before. One write in flight at a time, in order; `close()` waits.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
from collections.abc import Callable
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.atomic import write_atomic
from gcsd.vehicle.mission.effects import PlanChanged, Send, Text


class PlanWriter:
    def __init__(self, errors, now: Callable[[], float], write: Callable[[Path, str], None] = write_atomic) -> None:
        self.errors = errors
        self._now = now
        self.write = write  # the disk (gcsd.atomic); a test may slow it down
        self.deferring = False  # set by the mission service around a finished upload
        self._pending: tuple | None = None
        self._executor: concurrent.futures.ThreadPoolExecutor | None = None

    def save(self, path: Path, text: str, store) -> None:
        """The stores' saver: now, or (deferring, in a loop) on the worker once `hold` is called."""
        if self.deferring and _loop_running():
            self._pending = (path, text, store, store.stored())
            return
        self.write(path, text)

    def deferred(self) -> bool:
        return self._pending is not None

    def hold(self, outputs: list, release: Callable[[list], None]) -> None:
        """Write the deferred plan on the worker; `release(outputs)` on the loop once it is durable."""
        path, text, store, previous = self._pending
        self._pending = None
        loop = asyncio.get_running_loop()
        if self._executor is None:
            self._executor = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="gcsd-plans")
        future = self._executor.submit(self.write, path, text)
        future.add_done_callback(
            lambda f: _call_soon(loop, self._written, f, outputs, store, previous, release))

    def _written(self, future, outputs: list, store, previous, release: Callable[[list], None]) -> None:
        with self.errors.guard("persist:plan", self._now(), plan=store.name):
            error = future.exception()
            if error is not None:
                store.load(previous)  # the old plan stays in force, as when a synchronous save failed
                outputs = _failed(outputs, store, error)
            release(outputs)

    def close(self) -> None:
        """A clean stop: the write in flight, if any, is on disk when this returns."""
        if self._executor is not None:
            self._executor.shutdown(wait=True)
            self._executor = None


def _failed(outputs: list, store, error: BaseException) -> list:
    out: list = []
    for o in outputs:
        if isinstance(o, PlanChanged):
            continue
        if isinstance(o, Send) and o.msg.get_type() == "MISSION_ACK" and o.msg.mission_type == store.mission_type:
            m = o.msg
            o = Send(o.channel, M.MAVLink_mission_ack_message(m.target_system, m.target_component,
                                                              M.MAV_MISSION_ERROR, m.mission_type))
        elif isinstance(o, Text) and o.severity == M.MAV_SEVERITY_INFO:
            continue  # "Flight plan received" and the like: it was not
        out.append(o)
    reason = getattr(error, "strerror", None) or error
    return [Text(M.MAV_SEVERITY_ERROR, f"{store.label} not saved: {reason}"), *out]


def _loop_running() -> bool:
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return False
    return True


def _call_soon(loop, fn, *args) -> None:
    try:
        loop.call_soon_threadsafe(fn, *args)
    except RuntimeError:  # the loop is closed: a stop; close() waited for the write
        pass
