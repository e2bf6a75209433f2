"""The daemon's lifetime: build the Daemon, serve until SIGINT/SIGTERM, stop cleanly.

A first signal asks for a clean stop (tasks cancelled, transports closed); a second one while
stopping exits at once. Returns the process exit code: 0 clean stop, 1 failure, 2 a bad
configuration found before anything started: preflight.prepare (state_dir, FTP roots,
params_file, tlog) or a ConfigError while the vehicles are built (a bad params_file line); each
problem is one ``FILE:LINE: key.path: what`` line on stderr, as check-config prints them.
Before anything reads or writes state, the daemon locks state_dir (statelock.py): a second
daemon on the same state_dir exits 1 with one line naming the pid that holds it, having
changed nothing (no socket rebound, no mav.parm rewritten).
Once it is ready (every server channel bound, every client channel tried once) the daemon registers its control socket (control.register) so that
`gcsd status` finds it from any directory; the registration is removed at the stop.
SIGHUP (`systemctl reload gcsd`) re-reads the configuration file and applies its channels
(livechannels.py); a bad file is logged, line by line, and changes nothing.
"""

from __future__ import annotations

import asyncio
import gc
import signal
import sys
from pathlib import Path

import structlog

from gcsd.api import control
from gcsd.config import Config, ConfigError, load_config, preflight
from gcsd.config.schema import LOCAL_TYPE
from gcsd.daemon import statelock
from gcsd.daemon.daemon import Daemon
from gcsd.daemon.notify import Notifier
from gcsd.links import tcpserver
from gcsd.links.transport import ChannelStartError

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
    gcs_ref: list[Daemon] = []
    loop.add_signal_handler(signal.SIGHUP, lambda: gcs_ref and _reload(gcs_ref[0], loop))
    lock = None
    try:
        problems = preflight.prepare(config)
        if problems:
            raise ConfigError(problems)
        lock = statelock.acquire(Path(config.state_dir))  # before anything reads or writes state
        limit, needed = tcpserver.ensure_descriptor_budget(tcpserver.descriptors_needed(config.channels))
        if limit < needed:  # the hard limit is lower: connections may be refused (counted, tcpserver.py)
            log.warning("descriptor_budget_short", limit=limit, needed=needed)
        gcs = Daemon(config)
        gcs_ref.append(gcs)
        log.info(
            "daemon_started", vehicle=config.vehicle.type, sysid=config.vehicle.sysid,
            compid=config.vehicle.compid, count=config.vehicle.count, channels=len(gcs.channels),
        )
        notifier = Notifier()
        await _run_with_notify(gcs, stop, notifier)
    except ConfigError as exc:
        for problem in exc.problems:
            print(problem, file=sys.stderr)
        return 2
    except (ChannelStartError, statelock.StateDirBusy) as exc:  # one clear line, no traceback
        log.error("daemon_failed", error=str(exc))
        print(f"gcsd: {exc}", file=sys.stderr)
        return 1
    except Exception:
        log.exception("daemon_failed")
        return 1
    finally:
        for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            loop.remove_signal_handler(signum)
        if lock is not None:
            lock.release()
    log.info("daemon_stopped")
    return 0


def _reload(gcs: Daemon, loop: asyncio.AbstractEventLoop) -> None:
    """SIGHUP: write out changed state (parameters, signing timestamp), then re-read the
    configuration file and apply its channels (livechannels.py); a bad file is logged, line by
    line, and changes nothing. The daemon keeps running whatever the file says."""
    gcs.sync_state()
    path = gcs.config.source.file
    if path is None:
        log.warning("reload_ignored", reason="running the built-in default configuration: no file to re-read")
        return
    try:
        config = load_config(path)
    except ConfigError as exc:
        for problem in exc.problems:
            log.error("reload_refused", problem=problem)
        return
    log.info("reload_requested", config=path)
    task = loop.create_task(gcs.live.reload(config))
    _reloads.add(task)
    task.add_done_callback(_reloaded)


_reloads: set[asyncio.Task] = set()


def _reloaded(task: asyncio.Task) -> None:
    _reloads.discard(task)
    if not task.cancelled() and task.exception() is not None:
        log.error("reload_failed", error=repr(task.exception()))


def ready_status(gcs: Daemon) -> str:
    """systemd's status line at READY: the MAVLink channels open (the HTTP API's own channel is
    none of them, config_schema.mavlink_slot) and where the API listens, or why it does not."""
    mavlink = [ch for ch in gcs.channels if ch.config.type != LOCAL_TYPE]
    text = f"{sum(1 for ch in mavlink if ch.index in gcs.opened)} of {len(mavlink)} channels open"
    if gcs.http is None:
        return text
    http = gcs.http.state()
    if http["listening"] is not None:
        return f"{text}, HTTP API on {http['listening']}"
    return f"{text}, HTTP API not listening on {http['address']} ({http['error']}; retrying)"


async def _run_with_notify(gcs: Daemon, stop: asyncio.Event, notifier: Notifier) -> None:
    """Run the Daemon; tell systemd when it is ready (servers bound, clients tried), and ping its watchdog
    from the loop."""

    async def tell_systemd() -> None:
        await gcs.ready.wait()
        registration.append(control.register(gcs.config))
        status = ready_status(gcs)
        notifier.ready(status)
        log.info("daemon_ready", status=status, notify=notifier.enabled)
        # What start-up built (pymavlink's dialect, the parameter tables, the vehicles) lives as
        # long as the daemon: out of the collector's sight, so that the collections the packet
        # path's short-lived objects cause stay short (issue 19: 3-4 % of a routing daemon's time).
        gc.freeze()
        interval = notifier.watchdog_interval_s
        while interval:
            notifier.watchdog()
            await asyncio.sleep(interval)

    registration: list[control.Registration] = []
    helper = asyncio.create_task(tell_systemd())
    try:
        await gcs.run(stop)
    finally:
        helper.cancel()
        for entry in registration:
            entry.remove()
        notifier.stopping()
