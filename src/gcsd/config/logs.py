"""The `flight_logs` section (SPEC.md "Flight logs"), read by config.py's reader.

    flight_logs:
      dir: logs          # relative to state_dir (per vehicle); also visible over FTP as logs/
      capture: false     # take DataFlash logs a flight controller streams over MAVLink
      channels: []       # the channels the flight controller is on (empty: every channel)
      simulated: true    # the simulated vehicle writes its own DataFlash log while armed
      max_files: 100     # the oldest logs are deleted first
      min_free_mb: 100   # never fill the disk below this; the oldest logs go first

`dir` must be a directory under state_dir ("." would put the signing key beside the logs and
hand it to FTP clients through logs/); `channels` must name configured channels.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import PurePath

from gcsd.config.reader import Field, Reader

FLIGHT_LOGS_KEYS = ("dir", "capture", "channels", "simulated", "max_files", "min_free_mb")
MAX_MAX_FILES = 10_000
MAX_MIN_FREE_MB = 1_000_000


@dataclass(frozen=True)
class FlightLogsConfig:
    dir: str = "logs"
    capture: bool = False
    channels: tuple[str, ...] = ()  # channel names; empty: every channel
    simulated: bool = True
    max_files: int = 100
    min_free_mb: int = 100


def read_flight_logs(r: Reader, f: Field, channel_names: list[str]) -> FlightLogsConfig:
    s = r.section(f, FLIGHT_LOGS_KEYS)
    d = FlightLogsConfig()
    names = []
    for item in r.sequence(s["channels"]):
        name = r.text(item, None)
        if name is None:
            continue
        if name not in channel_names:
            r.problem(item, f"no channel is named {name!r} (channels: {', '.join(channel_names)})")
        elif name in names:
            r.problem(item, f"channel {name!r} is listed twice")
        else:
            names.append(name)
    return FlightLogsConfig(
        dir=_log_dir(r, s["dir"], d.dir),
        capture=r.boolean(s["capture"], d.capture),
        channels=tuple(names),
        simulated=r.boolean(s["simulated"], d.simulated),
        max_files=r.integer(s["max_files"], d.max_files, 1, MAX_MAX_FILES),
        min_free_mb=r.integer(s["min_free_mb"], d.min_free_mb, 0, MAX_MIN_FREE_MB),
    )


def _log_dir(r: Reader, f: Field, default: str) -> str:
    path = PurePath(r.path(f, default))
    if path.is_absolute() or ".." in path.parts:
        return r.reject(f, "a path relative to state_dir without '..'", default)
    if not path.parts:
        r.problem(f, "must be a directory under state_dir, not state_dir itself "
                     "(FTP clients would see the signing key and the saved parameters under logs/)")
        return default
    return str(path)
