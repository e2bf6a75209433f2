"""Channels at run time (SPEC.md "Companion routing"): `gcsd channel add|remove`, channels.yaml and
the SIGHUP reload.

A channel keeps its index (its slot: SRn_ parameters, signing link id, route table entries) for
its whole life. Removing one closes its transport, forgets its peers and its routes, and leaves
a retired slot, which the next added channel takes (the lowest first) before a new slot is
appended; at most MAX_CHANNELS slots exist. Every other channel is untouched: its task, peers,
routes and counters stay as they were.

- `add(spec)`: a spec is what `gcsd channel add NAME TYPE ADDRESS [--baud N] [--option X]...`
  sends: {name, type, address | device, baud?, options?}. It is checked as the configuration
  is (the same reader: config.py), and against the running channels (unique name, no shared
  port, target or device); a problem is one line without FILE:LINE. A server channel must bind
  at once (else the slot is given back and the error returned); a client channel is retried
  with its backoff like any other.
- Channels added at run time are kept in `state_dir/channels.yaml` (written atomically) and
  restored at the next start, after the configured ones; a restored entry that no longer fits
  (a clash with a channel now in the file) is skipped with a logged error.
- `reload(config)` (SIGHUP, `systemctl reload gcsd`): the file's channels against the running
  ones from the file, by name: equal ones are untouched, changed ones are reopened in their
  slot, gone ones closed, new ones opened. Channels added at run time are not the file's and
  stay. Other sections (vehicle, signing, routing...) need a restart: a change there is logged,
  not applied. A bad file is reported by the caller and changes nothing.
"""

from __future__ import annotations

import asyncio
import re
from dataclasses import dataclass
from pathlib import Path

import structlog
import yaml

from gcsd.atomic import write_atomic
from gcsd.config import MAX_CHANNELS, Config, ConfigError, _clash, parse_config
from gcsd.config.schema import ChannelConfig
from gcsd.links.channel import Channel
from gcsd.links.transport import ChannelStartError, run_channel

log = structlog.get_logger("gcsd.daemon.livechannels")

FILE_NAME = "channels.yaml"
FIRST_OPEN_S = 10.0
SPEC_KEYS = ("name", "type", "address", "device", "baud", "options")
_WHERE = re.compile(r"^[^\n]*?:\d+: (?:channels\[0\]\.?)?")
_RESTART_SECTIONS = ("vehicle", "state_dir", "params_file", "gcs", "mission", "ftp", "signing", "log",
                     "serial_control", "routing", "http")


def channel_from_spec(spec: dict, running: list[ChannelConfig]) -> tuple[ChannelConfig | None, str | None]:
    """A runtime channel's spec, checked as the configuration is: (config, None) or (None, why not)."""
    if not isinstance(spec, dict) or set(spec) - set(SPEC_KEYS):
        return None, f"expected the keys {', '.join(SPEC_KEYS)}"
    try:
        channel = parse_config(yaml.safe_dump({"channels": [spec]}), "channel").channels[0]
    except ConfigError as exc:
        return None, "; ".join(_WHERE.sub("", p) for p in exc.problems)
    for other in running:
        if other.name == channel.name:
            return None, f"name: a channel named {channel.name!r} is already running"
        clash = _clash(channel, other)
        if clash:
            return None, f"{'device' if channel.type == 'serial' else 'address'}: {clash} channel {other.name}"
    return channel, None


@dataclass(frozen=True)
class ReloadPlan:
    close: tuple[str, ...]
    reopen: tuple[ChannelConfig, ...]
    open: tuple[ChannelConfig, ...]


def plan_reload(old: tuple[ChannelConfig, ...], new: tuple[ChannelConfig, ...]) -> ReloadPlan:
    """What a reload changes: by name, equal channels are untouched."""
    before = {c.name: c for c in old}
    after = {c.name: c for c in new}
    return ReloadPlan(close=tuple(n for n in before if n not in after),
                      reopen=tuple(c for n, c in after.items() if n in before and before[n] != c),
                      open=tuple(c for n, c in after.items() if n not in before))


def restart_sections(old: Config, new: Config) -> list[str]:
    return [name for name in _RESTART_SECTIONS if getattr(old, name) != getattr(new, name)]


def load_specs(state_dir: Path, configured: tuple[ChannelConfig, ...]) -> list[tuple[dict, ChannelConfig]]:
    """channels.yaml's runtime channels that still fit beside the configured ones."""
    path = Path(state_dir) / FILE_NAME
    try:
        document = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        return []
    except (OSError, yaml.YAMLError) as exc:
        log.error("runtime_channels_unreadable", path=str(path), error=str(exc))
        return []
    specs = document.get("channels") if isinstance(document, dict) else None
    out: list[tuple[dict, ChannelConfig]] = []
    for spec in specs if isinstance(specs, list) else []:
        running = [*configured, *(c for _, c in out)]
        channel, error = channel_from_spec(spec, running)
        if channel is None or len(running) >= MAX_CHANNELS:
            log.error("runtime_channel_skipped", path=str(path), spec=spec, error=error or "too many channels")
            continue
        out.append((spec, channel))
    return out


class LiveChannels:
    """The channel tasks of one Daemon, and the channels added, removed and reloaded while it runs.
    Reaches into the Daemon's per-channel tables (a friend of daemon.py; see `Daemon.attach`)."""

    def __init__(self, gcs, restored: list[tuple[dict, ChannelConfig]]) -> None:
        self.gcs = gcs
        self.path = Path(gcs.config.state_dir) / FILE_NAME
        self.specs: dict[str, dict] = {c.name: spec for spec, c in restored}  # runtime channels, by name
        self.from_file = {c.name for c in gcs.config.channels}
        self.tasks: dict[int, asyncio.Task] = {}
        self._tg: asyncio.TaskGroup | None = None
        self._lock = asyncio.Lock()

    def start(self, tg: asyncio.TaskGroup) -> None:
        self._tg = tg
        for ch in self.gcs.channels:
            self.tasks[ch.index] = tg.create_task(self._run(ch), name=ch.name)

    def _run(self, ch: Channel, started: asyncio.Future | None = None):
        gcs = self.gcs

        def opened(channel: Channel, ok: bool) -> None:
            gcs._opened(channel, ok)
            if started is not None and not started.done():
                started.set_result(None)

        async def serve() -> None:
            try:
                await run_channel(ch, gcs.send_pass, gcs._wakeups[ch.index], opened, gcs.errors.failed)
            except ChannelStartError as exc:
                if started is None:
                    raise  # a configured server that cannot bind at start: the daemon does not start
                if not started.done():
                    started.set_result(str(exc))

        return serve()

    def running(self) -> list[Channel]:
        return [ch for ch in self.gcs.channels if not ch.retired]

    # --- gcsd channel add / remove ------------------------------------------------------------
    async def add(self, spec: dict) -> str | None:
        async with self._lock:
            channel, error = channel_from_spec(spec, [c.config for c in self.running()])
            if channel is None:
                return error
            error = await self._open(channel)
            if error is None:
                self.specs[channel.name] = {k: v for k, v in spec.items() if v is not None}
                self._save()
            return error

    async def remove(self, name: str) -> str | None:
        async with self._lock:
            ch = next((c for c in self.running() if c.name == name), None)
            if ch is None:
                return f"no channel named {name!r} is running"
            if ch.config.type == "local":
                return f"{name} is the HTTP API's own channel: set http.address to null and restart to remove it"
            await self._close(ch)
            if self.specs.pop(name, None) is not None:
                self._save()
            self.from_file.discard(name)
            return None

    def _save(self) -> None:
        try:
            write_atomic(self.path, yaml.safe_dump({"channels": list(self.specs.values())}, sort_keys=False),
                         mode=0o600)
        except OSError as exc:
            log.error("runtime_channels_save_failed", path=str(self.path), error=str(exc))

    # --- SIGHUP ----------------------------------------------------------------------------
    async def reload(self, config: Config) -> None:
        async with self._lock:
            old = self.gcs.config
            sections = restart_sections(old, config)
            if sections:
                log.warning("reload_needs_restart", sections=sections)
            running = {c.name: c for c in self.running()}
            plan = plan_reload(tuple(running[n].config for n in self.from_file if n in running), config.channels)
            for name in plan.close:
                await self._close(running[name])
            for channel in plan.reopen:
                old_ch = running[channel.name]
                await self._close(old_ch)
                await self._report(channel, await self._open(channel, prefer=old_ch.index))
            for channel in plan.open:
                clash = next((c.name for c in self.running() if c.name == channel.name or _clash(channel, c.config)),
                             None)
                await self._report(channel, f"clashes with channel {clash}" if clash else await self._open(channel))
            self.from_file = {c.name for c in config.channels}
            log.info("configuration_reloaded", closed=list(plan.close), reopened=[c.name for c in plan.reopen],
                     opened=[c.name for c in plan.open])

    async def _report(self, channel: ChannelConfig, error: str | None) -> None:
        if error is not None:
            log.error("reload_channel_failed", channel=channel.name, error=error)

    # --- one slot ----------------------------------------------------------------------------
    async def _open(self, config: ChannelConfig, prefer: int | None = None) -> str | None:
        gcs = self.gcs
        index = gcs.free_slot(prefer)
        if index is None:
            return f"at most {MAX_CHANNELS} channels (SR0_ .. SR9_)"
        ch = gcs.attach(index, config)
        started = asyncio.get_running_loop().create_future()
        self.tasks[index] = self._tg.create_task(self._run(ch, started), name=ch.name)
        try:  # a server binds or fails at once; a client reports its first attempt
            error = await asyncio.wait_for(asyncio.shield(started), FIRST_OPEN_S)
        except TimeoutError:
            error = None  # still trying (a slow name lookup): it goes on with its backoff
        if error is not None:
            self.tasks.pop(index, None)
            gcs.detach(ch)
            return error
        log.info("channel_added", channel=ch.name, index=index)
        return None

    async def _close(self, ch: Channel) -> None:
        task = self.tasks.pop(ch.index, None)
        if task is not None:
            task.cancel()
            await asyncio.wait({task})
        self.gcs.detach(ch)
        log.info("channel_removed", channel=ch.name, index=ch.index)
