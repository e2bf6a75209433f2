"""SYSID_THISMAV across the vehicles of one daemon (a swarm, `vehicle.count` > 1): each vehicle
must keep a system id of its own, or two answer as one and the other cannot be reached.

- At run time (`clash`): a PARAM_SET of SYSID_THISMAV to the sysid another vehicle of the daemon
  has now, or will have at its next start (its own SYSID_THISMAV, which acts at the next start),
  is refused: the ground station gets the old value back and a STATUSTEXT saying why, as
  ArduPilot answers a refused set. Any other value is stored (as every parameter is).
- At start (`start_sysids`): each vehicle wants its saved SYSID_THISMAV. A value that is not a
  MAVLink system id (1..255), or that another vehicle also wants, falls back to the vehicle's
  configured sysid (vehicle.sysid + its index); repeated until no two are the same. Configured
  sysids are distinct and a fallback never moves again, so this ends, at worst with every
  vehicle on its configured sysid. Only the sysid changes: the vehicle keeps its state
  directory, its other parameters and its plans; the caller logs the fallback and saves it.

Pure: lists in, lists or a reason out.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

NAME = "SYSID_THISMAV"


def valid(sysid: float) -> bool:
    return float(sysid).is_integer() and 1 <= sysid <= 255


def start_sysids(configured: Sequence[int], wanted: Sequence[float]) -> list[int]:
    """The sysid each vehicle starts with (see the module docstring)."""
    chosen = [int(w) if valid(w) else c for c, w in zip(configured, wanted, strict=True)]
    moved = True
    while moved:
        moved = False
        counts = Counter(chosen)
        for i, sysid in enumerate(chosen):
            if counts[sysid] > 1 and sysid != configured[i]:
                chosen[i] = configured[i]
                moved = True
    return chosen


def clash(index: int, value: float, current: Sequence[int], pending: Sequence[float]) -> str | None:
    """Why vehicle `index` may not take SYSID_THISMAV `value` (the value as stored), or None.
    `current`: each vehicle's sysid now; `pending`: each one's SYSID_THISMAV (its next start)."""
    for j, (now, later) in enumerate(zip(current, pending, strict=True)):
        if j != index and value in (now, later):
            return f"{NAME} {int(value)} refused: another vehicle's sysid"
    return None
