"""What the mission transfer machine takes and gives back (transfer.py, download.py): the `Origin`
of a request, and its outputs: `Send` (a message on a channel; an `optional` copy goes only when
it would go out at once), `Text` (a STATUSTEXT, to one channel or every ground station) and
`PlanChanged` (a store's plan was replaced). Frozen data: no state, no sockets, no clock."""

from __future__ import annotations

from collections.abc import Hashable
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Origin:
    """Who sent a request and where from; `channel` is opaque (replies go back through it)."""

    sysid: int
    compid: int
    channel: Hashable
    mavlink1: bool = False

    @property
    def node(self) -> tuple[int, int]:
        return self.sysid, self.compid


@dataclass(frozen=True, slots=True)
class Send:
    channel: Hashable
    msg: object
    optional: bool = False  # a copy for a lossy link: only if the byte budget has room


@dataclass(frozen=True, slots=True)
class Text:
    severity: int
    text: str
    channel: Hashable | None = None  # None: every ground station


@dataclass(frozen=True, slots=True)
class PlanChanged:
    mission_type: int
    count: int


Output = Send | Text | PlanChanged
