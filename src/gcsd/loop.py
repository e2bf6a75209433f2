"""The event loop the daemon runs on: uvloop (libuv) where it is installed, else asyncio's own.

uvloop is a dependency (wheels for x86_64 and aarch64 Linux); on a machine where it cannot be
installed or imported, `run` falls back to the standard loop, which serves the same daemon
slower. `GCSD_LOOP=asyncio` forces the standard loop (a comparison, or a suspected loop bug).
Measured in bench/RESULTS.md ("Routing at C++ cost").
"""

from __future__ import annotations

import asyncio
import os
from collections.abc import Callable, Coroutine
from typing import Any


def loop_factory() -> Callable[[], asyncio.AbstractEventLoop] | None:
    """uvloop's loop factory, or None for asyncio's default."""
    if os.environ.get("GCSD_LOOP", "").lower() == "asyncio":
        return None
    try:
        import uvloop
    except ImportError:
        return None
    return uvloop.new_event_loop


def loop_name() -> str:
    return "asyncio" if loop_factory() is None else "uvloop"


def run(main: Coroutine[Any, Any, Any]):
    """asyncio.run(main) on the chosen loop."""
    with asyncio.Runner(loop_factory=loop_factory()) as runner:
        return runner.run(main)
