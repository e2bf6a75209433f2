"""WriteBehind on a real event loop and real files: a burst of parameter sets is coalesced into
at most one write per second, the writes happen on a worker thread while the loop keeps its
timing, a clean stop flushes, a failed write is retried."""

from __future__ import annotations

import asyncio
import math
import threading
import time

from test_params_service import FakeChannel, FakeContext, defs, param_set

from gcsd.atomic import write_atomic
from gcsd.params import ParamStore
from gcsd.params.parmfile import read_parm
from gcsd.persist import WriteBehind
from gcsd.services.params import ParamService


class RecordingWrite:
    """write_atomic, recording when and on which thread, optionally slow or failing first."""

    def __init__(self, delay_s: float = 0.0, failures: int = 0) -> None:
        self.calls: list[tuple[float, str]] = []
        self.delay_s = delay_s
        self.failures = failures

    def __call__(self, path, text) -> None:
        self.calls.append((time.monotonic(), threading.current_thread().name))
        if self.failures:
            self.failures -= 1
            raise OSError(28, "No space left on device")
        time.sleep(self.delay_s)  # a slow disk: fsync of a busy SD card
        write_atomic(path, text)


def service_and_writer(tmp_path, write: RecordingWrite):
    svc = ParamService(FakeContext([FakeChannel(0)]), ParamStore(defs()), tmp_path / "mav.parm", now=time.monotonic())
    writer = WriteBehind(svc.save_path, svc, time.monotonic, write=write)
    svc.on_dirty = writer.kick
    return svc, writer


def test_a_burst_of_sets_is_two_writes_on_a_worker_thread_and_the_loop_never_waits(tmp_path):
    write = RecordingWrite(delay_s=0.3)
    svc, writer = service_and_writer(tmp_path, write)
    lateness: list[float] = []
    sets = 0

    async def ticker(stop: asyncio.Event) -> None:  # what a second client's requests see
        while not stop.is_set():
            before = time.monotonic()
            await asyncio.sleep(0.005)
            lateness.append(time.monotonic() - before - 0.005)

    burst_s = 0.0

    async def main() -> None:
        nonlocal sets, burst_s
        stop = asyncio.Event()
        tick = asyncio.create_task(ticker(stop))
        start = time.monotonic()
        for batch in range(100):  # 1 000 sets in 0.9 s, each one a change
            for _ in range(10):
                sets += 1
                param_set(svc, f"P{sets % 250:04d}", sets, now=time.monotonic())
            await asyncio.sleep(max(0.0, start + 0.009 * (batch + 1) - time.monotonic()))
        burst_s = time.monotonic() - start
        await asyncio.sleep(1.5)  # past the second write's deadline, and its 0.3 s of disk time
        stop.set()
        await tick
        writer.flush()

    asyncio.run(main())
    assert sets == 1000
    # the first change at once, then one write per second of burst (2 when the machine kept up)
    assert len(write.calls) == 1 + math.ceil(burst_s), (burst_s, write.calls)
    assert write.calls[1][0] - write.calls[0][0] >= 0.99
    assert all(name.startswith("gcsd-persist") for _, name in write.calls)
    assert max(lateness) < 0.2, f"the loop waited {max(lateness):.3f} s (a write takes 0.3 s)"
    values, problems = read_parm(tmp_path / "mav.parm")
    assert problems == [] and values[f"P{sets % 250:04d}"] == sets


def test_flush_waits_for_the_write_in_flight_and_writes_what_is_left(tmp_path):
    write = RecordingWrite(delay_s=0.3)
    svc, writer = service_and_writer(tmp_path, write)

    async def main() -> None:
        param_set(svc, "ANGLE_MAX", 4500, now=time.monotonic())
        while not write.calls:  # the first write has started on the worker
            await asyncio.sleep(0.01)
        param_set(svc, "ANGLE_MAX", 4600, now=time.monotonic())
        writer.flush()  # a clean stop: blocks until both are on disk

    asyncio.run(main())
    assert len(write.calls) == 2 and writer.writes == 2
    assert read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4600


def test_a_failed_write_is_reported_and_retried_a_second_later(tmp_path):
    write = RecordingWrite(failures=1)
    svc, writer = service_and_writer(tmp_path, write)

    async def main() -> None:
        param_set(svc, "ANGLE_MAX", 4500, now=time.monotonic())
        deadline = time.monotonic() + 3.0
        while writer.writes == 0 and time.monotonic() < deadline:
            await asyncio.sleep(0.02)
        writer.flush()

    asyncio.run(main())
    assert len(write.calls) == 2 and writer.writes == 1
    assert 0.9 <= write.calls[1][0] - write.calls[0][0] < 1.5
    assert [t[1] for t in svc.ctx.texts] == ["Param save failed"]
    assert read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4500


def test_without_an_event_loop_a_due_write_is_made_at_once_and_the_rest_by_flush(tmp_path):
    write = RecordingWrite()
    svc, writer = service_and_writer(tmp_path, write)
    param_set(svc, "ANGLE_MAX", 4500, now=time.monotonic())
    assert len(write.calls) == 1 and write.calls[0][1] == threading.current_thread().name
    param_set(svc, "ANGLE_MAX", 4600, now=time.monotonic())  # within the second: waits
    assert len(write.calls) == 1 and read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4500
    writer.flush()
    assert len(write.calls) == 2 and read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4600


def test_sync_writes_what_is_dirty_now_and_the_write_behind_goes_on(tmp_path):
    write = RecordingWrite(delay_s=0.1)
    svc, writer = service_and_writer(tmp_path, write)

    async def main() -> None:
        param_set(svc, "ANGLE_MAX", 4500, now=time.monotonic())
        while not write.calls:
            await asyncio.sleep(0.01)
        param_set(svc, "ANGLE_MAX", 4600, now=time.monotonic())  # due only a second after the first
        writer.sync()  # SIGHUP: waits for the write in flight, writes the rest now
        assert writer.writes == 2 and read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4600
        param_set(svc, "ANGLE_MAX", 4700, now=time.monotonic())
        deadline = time.monotonic() + 3.0
        while writer.writes < 3 and time.monotonic() < deadline:
            await asyncio.sleep(0.02)
        assert writer.writes == 3, "after a sync, changes are still written behind"
        writer.flush()

    asyncio.run(main())
    assert read_parm(tmp_path / "mav.parm")[0]["ANGLE_MAX"] == 4700
