"""WriteBehind on a virtual-time event loop and real files: a burst of parameter sets is coalesced
into at most one write per second, the writes happen on a worker thread while the loop runs on,
a clean stop flushes, a failed write is retried a second later.

`VirtualClockLoop` is a real asyncio loop (real sockets, real call_soon_threadsafe from the
worker) whose clock moves only when it would otherwise sleep: it jumps to its next timer at once.
While a write is in flight (the source has handed out a text and has not had its outcome yet)
the clock stands still and the loop waits for the worker for real, so the disk's time never
looks like loop time and every timing below is exact.
"""

from __future__ import annotations

import asyncio
import math
import selectors
import threading

import pytest
from test_params_service import FakeChannel, FakeContext, defs, param_set

from gcsd.atomic import write_atomic
from gcsd.persist import WriteBehind
from gcsd.vehicle.params import ParamStore
from gcsd.vehicle.params.parmfile import read_parm
from gcsd.vehicle.services.params import ParamService

HOLD_WAIT_S = 5.0  # the longest real wait for a worker; a stuck test then fails instead of hanging


class VirtualClockLoop(asyncio.SelectorEventLoop):
    def __init__(self, hold=lambda: False) -> None:
        self.virtual_s = 0.0
        self._hold = hold
        super().__init__(selector=_VirtualSelector(self))

    def time(self) -> float:
        return self.virtual_s


class _VirtualSelector(selectors.DefaultSelector):
    def __init__(self, loop: VirtualClockLoop) -> None:
        super().__init__()
        self._virtual_loop = loop

    def select(self, timeout=None):
        ready = super().select(0)
        if ready or timeout == 0:
            return ready
        loop = self._virtual_loop
        if timeout is None or loop._hold():  # nothing scheduled, or the worker is writing: real wait
            ready = super().select(HOLD_WAIT_S)
            if ready or timeout is None:
                return ready
        loop.virtual_s += timeout
        return []


class CountingSource:
    """The service as WriteBehind's source, counting the writes in flight (for the loop's hold)."""

    def __init__(self, svc: ParamService) -> None:
        self.svc = svc
        self.in_flight = 0

    def persist_deadline(self):
        return self.svc.persist_deadline()

    def take_persist(self, now: float, force: bool = False):
        text = self.svc.take_persist(now, force)
        self.in_flight += text is not None
        return text

    def persist_done(self) -> None:
        self.in_flight -= 1
        self.svc.persist_done()

    def persist_failed(self, error: str) -> None:
        self.in_flight -= 1
        self.svc.persist_failed(error)


class RecordingWrite:
    """write_atomic, recording when (loop time) and on which thread; it may fail first, or wait at
    a gate the test opens (a slow disk)."""

    def __init__(self, clock, failures: int = 0, gate: threading.Event | None = None) -> None:
        self.clock = clock
        self.calls: list[tuple[float, str]] = []
        self.failures = failures
        self.gate = gate
        self.entered = threading.Event()

    def __call__(self, path, text) -> None:
        self.calls.append((self.clock(), threading.current_thread().name))
        self.entered.set()
        if self.gate is not None:
            assert self.gate.wait(HOLD_WAIT_S), "the disk was never released"
        if self.failures:
            self.failures -= 1
            raise OSError(28, "No space left on device")
        write_atomic(path, text)


def run(tmp_path, body, failures: int = 0, gate: threading.Event | None = None):
    """body(svc, writer, write, loop) as a coroutine on a VirtualClockLoop; returns (svc, writer, write)."""
    source_box: list[CountingSource] = []
    loop = VirtualClockLoop(hold=lambda: bool(source_box) and source_box[0].in_flight > 0)
    svc = ParamService(FakeContext([FakeChannel(0)]), ParamStore(defs()), tmp_path / "mav.parm", now=0.0)
    source = CountingSource(svc)
    source_box.append(source)
    write = RecordingWrite(loop.time, failures, gate)
    writer = WriteBehind(svc.save_path, source, loop.time, write=write)
    svc.on_dirty = writer.kick
    try:
        loop.run_until_complete(body(svc, writer, write, loop))
    finally:
        loop.close()
    return svc, writer, write


def test_a_burst_of_sets_is_one_write_at_once_then_one_per_second_on_a_worker_thread(tmp_path):
    sets = 0

    async def body(svc, writer, write, loop) -> None:
        nonlocal sets
        for batch in range(100):  # 1 000 sets in 0.9 s, each one a change
            for _ in range(10):
                sets += 1
                param_set(svc, f"P{sets % 250:04d}", sets, now=loop.time())
            await asyncio.sleep(0.009)
        await asyncio.sleep(1.5)  # past the second write's deadline
        writer.flush()

    _, _, write = run(tmp_path, body)
    assert sets == 1000
    # the first change at once, then one write per second of burst (0.9 s: one more)
    assert [t for t, _ in write.calls] == pytest.approx([0.0, 1.0])
    assert all(name.startswith("gcsd-persist") for _, name in write.calls)
    values, problems = read_parm(tmp_path / "mav.parm")
    assert problems == [] and values[f"P{sets % 250:04d}"] == sets


def test_the_loop_runs_on_while_a_write_waits_for_the_disk(tmp_path):
    gate = threading.Event()
    handled_meanwhile = []

    async def body(svc, writer, write, loop) -> None:
        param_set(svc, "ANGLE_MAX", 4500, now=loop.time())
        await asyncio.sleep(0)  # the timer (due now) hands the write to the worker
        await asyncio.sleep(0)
        assert await asyncio.to_thread(write.entered.wait, HOLD_WAIT_S), "no write started"
        for value in (4600, 4700, 4800):  # the disk is stuck: the loop keeps serving sets
            param_set(svc, "ANGLE_MAX", value, now=loop.time())
            handled_meanwhile.append(svc.store.get("ANGLE_MAX"))
            await asyncio.sleep(0)
        gate.set()
        writer.flush()

    _, writer, write = run(tmp_path, body, gate=gate)
    assert handled_meanwhile == [4600, 4700, 4800]
    assert write.calls[0][1].startswith("gcsd-persist") and writer.writes == 2
    assert read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4800


def test_flush_waits_for_the_write_in_flight_and_writes_what_is_left(tmp_path):
    gate = threading.Event()

    async def body(svc, writer, write, loop) -> None:
        param_set(svc, "ANGLE_MAX", 4500, now=loop.time())
        assert await asyncio.to_thread(write.entered.wait, HOLD_WAIT_S)  # the first write is on the worker
        param_set(svc, "ANGLE_MAX", 4600, now=loop.time())
        threading.Timer(0.05, gate.set).start()  # the disk finishes while flush() already waits
        writer.flush()  # a clean stop: blocks until both are on disk

    _, writer, write = run(tmp_path, body, gate=gate)
    assert len(write.calls) == 2 and writer.writes == 2
    assert read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4600


def test_a_failed_write_is_reported_and_retried_a_second_later(tmp_path):
    async def body(svc, writer, write, loop) -> None:
        param_set(svc, "ANGLE_MAX", 4500, now=loop.time())
        while writer.writes == 0 and loop.time() < 3.0:
            await asyncio.sleep(0.02)
        writer.flush()

    svc, writer, write = run(tmp_path, body, failures=1)
    assert len(write.calls) == 2 and writer.writes == 1
    assert math.isclose(write.calls[1][0] - write.calls[0][0], 1.0)
    assert [t[1] for t in svc.ctx.texts] == ["Param save failed"]
    assert read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4500


def test_without_an_event_loop_a_due_write_is_made_at_once_and_the_rest_by_flush(tmp_path):
    clock = [0.0]
    svc = ParamService(FakeContext([FakeChannel(0)]), ParamStore(defs()), tmp_path / "mav.parm", now=0.0)
    write = RecordingWrite(lambda: clock[0])
    writer = WriteBehind(svc.save_path, svc, lambda: clock[0], write=write)
    svc.on_dirty = writer.kick
    param_set(svc, "ANGLE_MAX", 4500, now=0.0)
    assert len(write.calls) == 1 and write.calls[0][1] == threading.current_thread().name
    param_set(svc, "ANGLE_MAX", 4600, now=0.1)  # within the second: waits
    assert len(write.calls) == 1 and read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4500
    writer.flush()
    assert len(write.calls) == 2 and read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4600


def test_sync_writes_what_is_dirty_now_and_the_write_behind_goes_on(tmp_path):
    async def body(svc, writer, write, loop) -> None:
        param_set(svc, "ANGLE_MAX", 4500, now=loop.time())
        while not write.calls:
            await asyncio.sleep(0.01)
        param_set(svc, "ANGLE_MAX", 4600, now=loop.time())  # due only a second after the first
        writer.sync()  # SIGHUP: waits for the write in flight, writes the rest now
        assert writer.writes == 2 and read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4600
        param_set(svc, "ANGLE_MAX", 4700, now=loop.time())
        while writer.writes < 3 and loop.time() < 3.0:
            await asyncio.sleep(0.02)
        assert writer.writes == 3, "after a sync, changes are still written behind"
        writer.flush()

    run(tmp_path, body)
    assert read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4700
