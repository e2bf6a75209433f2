"""How a node gets its flight logs (called from the composition root).

- `log_dir(node_state_dir, config)`: the node's log directory, `flight_logs.dir` under the
  vehicle's state directory; the FTP service mounts it as `logs/`.
- `flight_log_service(node, config)`: the node's FlightLogService. Every node serves its own
  directory; a simulated vehicle writes its log there when `flight_logs.simulated`; node 0
  captures when `flight_logs.capture` (one owner of the flight controller's stream, even in a
  swarm), on the channels `flight_logs.channels` names (all when empty).
"""

from __future__ import annotations

from pathlib import Path

from gcsd.payloads.logs.capture import Capture
from gcsd.payloads.logs.service import FlightLogService
from gcsd.payloads.logs.store import LogStore


def log_dir(node_state_dir, config) -> Path:
    return Path(node_state_dir) / config.flight_logs.dir


def flight_log_service(node, config) -> FlightLogService:
    fl = config.flight_logs
    store = LogStore(log_dir(node.state_dir, config), fl.max_files, fl.min_free_mb)
    capture = None
    if fl.capture and node.index == 0:
        names = set(fl.channels)
        channels = frozenset(i for i, c in enumerate(config.channels) if c.name in names) if names else None
        capture = Capture(node.sysid, node.compid, channels)
    simulated = fl.simulated and node.autopilot.simulated and node.vehicle.can_arm
    # a vehicle that cannot arm is a companion computer: it answers only its own component, never
    # a request the flight controller it sits beside (same sysid, component 0 or 1) should answer
    return FlightLogService(node, store, simulated, capture, exact_component=not node.vehicle.can_arm)
