"""Several plans replaced as one, all or none (the HTTP `.plan`: mission, fence and rally). Pure.

`write_together([(transfer, items), ...])` has no state and no timer; it runs in two steps:
1. check: each plan passes every check an upload makes (MissionTransfer.check_write: DENIED
   while a ground station uploads that type, NO_SPACE above its limit, an item's own result,
   the whole plan's check). The first refusal returns at once and nothing has changed.
2. replace: each is saved and adopted in turn (PlanStore.replace: the file first). A save that
   fails (OSError) puts back, last first, the plans already replaced (saved again; if that save
   fails too, adopted again in memory and the failure told as text, so memory is never half
   new) and the whole write is refused with ERROR.
The outputs (PlanChanged for each plan on success, "<Plan> not saved" texts on a failed save)
are for the owner to run, as the transfer machine's are.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission.effects import Output, Text
from gcsd.vehicle.mission.items import MissionItem
from gcsd.vehicle.mission.transfer import ACCEPTED, ERROR, MissionTransfer

Items = tuple[MissionItem, ...]


@dataclass(frozen=True, slots=True)
class Written:
    result: int  # MAV_MISSION_RESULT
    refused_type: int | None = None  # the MAV_MISSION_TYPE that was refused
    reason: str | None = None
    limit: int = 0  # the refused plan's item limit (its store's max_items)
    outputs: list[Output] = field(default_factory=list)


def write_together(writes: Iterable[tuple[MissionTransfer, Items]]) -> Written:
    writes = [(t, tuple(items)) for t, items in writes]
    for t, items in writes:
        result, why = t.check_write(items)
        if result != ACCEPTED:
            return Written(result, t.mission_type, why, t.store.max_items)
    done: list[tuple[MissionTransfer, Items]] = []
    for t, items in writes:
        previous = t.store.stored()
        try:
            t.store.replace(items)
        except OSError as exc:
            failed = t.save_failed(exc)
            return Written(ERROR, t.mission_type, failed.text, t.store.max_items, [failed, *_put_back(done)])
        done.append((t, previous))
    outputs: list[Output] = []
    for t, _ in writes:
        outputs += t.written()
    return Written(ACCEPTED, outputs=outputs)


def _put_back(done: list[tuple[MissionTransfer, Items]]) -> list[Output]:
    out: list[Output] = []
    for t, previous in reversed(done):
        try:
            t.store.replace(previous)
        except OSError as exc:
            t.store.load(previous)  # memory as before the write; the file keeps the new plan
            out.append(Text(M.MAV_SEVERITY_ERROR, f"{t.store.label} not put back on disk: {exc.strerror or exc}"))
    return out
