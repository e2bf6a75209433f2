"""`gcsd logs [-c FILE] [--json]`: the flight logs a configuration keeps, without a daemon.

One directory per vehicle: `state_dir/DIR`, or `state_dir/vehicle-N/DIR` for vehicle N of a
swarm (DIR is `flight_logs.dir`), as the daemon lays them out. Each log is shown with the id a
ground station's LOG_REQUEST_LIST gets for it, its size, its start time (UTC) and its path.
"""

from __future__ import annotations

import datetime
from pathlib import Path

from gcsd.payloads.logs.store import LogStore


def log_dirs(config) -> list[tuple[int, Path]]:
    """(sysid, directory) per vehicle."""
    base, count, sysid = Path(config.state_dir), config.vehicle.count, config.vehicle.sysid
    if count == 1:
        return [(sysid, base / config.flight_logs.dir)]
    return [(sysid + i, base / f"vehicle-{i + 1}" / config.flight_logs.dir) for i in range(count)]


def list_logs(config) -> list[dict]:
    out = []
    for sysid, directory in log_dirs(config):
        store = LogStore(directory, config.flight_logs.max_files, config.flight_logs.min_free_mb)
        for e in store.entries():
            out.append({"sysid": sysid, "id": e.id, "name": e.name, "size": e.size, "time_utc": e.time_utc,
                        "path": str(directory / e.name)})
    return out


def format_logs(logs: list[dict], config) -> str:
    if not logs:
        dirs = ", ".join(str(d) for _, d in log_dirs(config))
        return f"no flight logs in {dirs}"
    lines = [f"{'sysid':>5} {'id':>4} {'size':>12}  {'started (UTC)':19}  path"]
    for log in logs:
        when = datetime.datetime.fromtimestamp(log["time_utc"], datetime.UTC).strftime("%Y-%m-%d %H:%M:%S")
        lines.append(f"{log['sysid']:>5} {log['id']:>4} {log['size']:>12}  {when}  {log['path']}")
    return "\n".join(lines)
