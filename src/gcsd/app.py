"""The daemon's lifetime: build the GCS, serve until SIGINT/SIGTERM, stop cleanly.

A first signal asks for a clean stop (tasks cancelled, transports closed); a second one while
stopping exits at once. Returns the process exit code: 0 clean stop, 1 failure.
"""

from __future__ import annotations

import asyncio
import signal

import structlog

from .config import Config
from .gcs import GCS

log = structlog.get_logger("gcsd")


async def run_daemon(config: Config) -> int:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    signals = 0

    def on_signal(signum: int) -> None:
        nonlocal signals
        signals += 1
        if signals > 1:
            log.warning("stop_forced", signal=signal.Signals(signum).name)
            raise SystemExit(1)
        log.info("stop_requested", signal=signal.Signals(signum).name)
        stop.set()

    for signum in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(signum, on_signal, signum)
    try:
        config.state_dir.mkdir(parents=True, exist_ok=True)
        gcs = GCS(config)
        log.info(
            "daemon_started", vehicle=config.vehicle.type, sysid=config.vehicle.sysid,
            compid=config.vehicle.compid, count=config.vehicle.count, channels=len(gcs.channels),
        )
        await gcs.run(stop)
    except Exception:
        log.exception("daemon_failed")
        return 1
    finally:
        for signum in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(signum)
    log.info("daemon_stopped")
    return 0
