"""Shared fixtures: the real daemon in a background thread, on ephemeral loopback ports.

`daemon(yaml_text_or_dict)` builds a Config from YAML (so tests use the same validation as
users), starts the GCS in its own thread and event loop, waits until every channel is open and
returns a `RunningDaemon` with `.port(name)` and `.stats()` (the channels' public counters). At
teardown the daemon is stopped and its thread joined. Clients are blocking pymavlink
connections, which is why the daemon gets its own loop.
"""

from __future__ import annotations

import asyncio
import fcntl
import os
import threading
from pathlib import Path

import pytest
import yaml

from gcsd.config import parse_config
from gcsd.daemon.daemon import Daemon

START_TIMEOUT_S = 5.0


class RunningDaemon:
    def __init__(self, config, backend=None, producers=None) -> None:
        self.config = config
        self.backend = backend  # gcsd.embed: backend(index) in place of the simulation
        self.producers = producers  # a telemetry table in place of gcsd.vehicle.telemetry.producers()
        self.gcs: Daemon | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._main, name="gcsd", daemon=True)

    def _main(self) -> None:
        async def body():
            self._loop = asyncio.get_running_loop()
            self._stop = asyncio.Event()
            self.gcs = Daemon(self.config, backend=self.backend, producers=self.producers)
            runner = asyncio.create_task(self.gcs.run(self._stop))
            await self.gcs.ready.wait()
            self._ready.set()
            await runner

        try:
            asyncio.run(body())
        except BaseException as exc:  # noqa: BLE001  (surfaced to the test by start()/stop())
            self._error = exc
            self._ready.set()

    def start(self) -> RunningDaemon:
        self._thread.start()
        if not self._ready.wait(START_TIMEOUT_S) or self._error:
            raise RuntimeError(f"daemon did not start: {self._error!r}")
        return self

    def stop(self) -> None:
        if self._loop is not None and self._stop is not None and self._thread.is_alive():
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(5.0)
        assert not self._thread.is_alive(), "daemon thread did not stop within 5 s"
        if self._error:
            raise self._error

    def http_url(self) -> str:
        host, port = self.gcs.http.address
        return f"http://{host}:{port}"

    def port(self, name: str) -> int:
        for ch in self.gcs.channels:
            if ch.name == name:
                return ch.local_address[1]
        raise KeyError(name)

    def status(self) -> dict:
        """What `gcsd status --json` shows (taken in the daemon's own thread)."""
        return asyncio.run_coroutine_threadsafe(_call(self.gcs.status), self._loop).result(5.0)

    def stats(self, name: str) -> dict[str, int]:
        for ch in self.gcs.channels:
            if ch.name == name:
                return ch.snapshot()
        raise KeyError(name)


async def _call(fn):
    return fn()


@pytest.fixture
def daemon(tmp_path: Path):
    started: list[RunningDaemon] = []

    def start(conf: str | dict, backend=None, producers=None) -> RunningDaemon:
        data = yaml.safe_load(conf) if isinstance(conf, str) else dict(conf)
        data.setdefault("state_dir", str(tmp_path / "state"))
        data.setdefault("http", {"address": "127.0.0.1:0"})  # as the channels: an ephemeral port
        config = parse_config(yaml.safe_dump(data), "test.yaml")
        d = RunningDaemon(config, backend, producers).start()
        started.append(d)
        return d

    yield start
    for d in started:
        d.stop()


def pytest_collection_modifyitems(config, items) -> None:
    """The tests marked slow or fault (a minute or more each, some of them) run first: under
    pytest-xdist (README's command) they then start at once on different workers, and the many
    short tests fill in around them instead of one long test starting last and running alone.
    The tests marked alone run last: each waits for the tests running on other workers to end."""
    def order(item) -> int:
        if item.get_closest_marker("alone"):
            return 2
        return 0 if item.get_closest_marker("slow") or item.get_closest_marker("fault") else 1

    items.sort(key=order)


@pytest.fixture(autouse=True)
def _alone_or_together(request, tmp_path_factory):
    """Under pytest-xdist a test marked `alone` (a real-time measurement that four tests at once on
    two cores would distort: a round trip, a latency) runs while no other test of the run does.
    Every test holds a shared lock while it runs, from before its own fixtures start to after
    they end; an `alone` test takes it exclusively. A gate taken before either keeps new tests
    from starting while an `alone` test waits, so it is not starved. Outside xdist every test
    runs alone anyway. The lock files are in the run's shared temporary directory."""
    if os.environ.get("PYTEST_XDIST_WORKER") is None:
        yield
        return
    root = tmp_path_factory.getbasetemp().parent
    alone = request.node.get_closest_marker("alone") is not None
    with (root / "alone.gate").open("a") as gate, (root / "alone.lock").open("a") as lock:
        fcntl.flock(gate, fcntl.LOCK_EX)
        try:
            fcntl.flock(lock, fcntl.LOCK_EX if alone else fcntl.LOCK_SH)
        finally:
            if not alone:
                fcntl.flock(gate, fcntl.LOCK_UN)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)
            if alone:
                fcntl.flock(gate, fcntl.LOCK_UN)
