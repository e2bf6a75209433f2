"""Missions, fence and rally on a vehicle node: the thin adapter around three MissionTransfers.

MISSION_* messages are routed by their mission_type to that type's machine (gcsd.vehicle.mission.transfer);
an unknown type gets MISSION_ACK UNSUPPORTED (requests for items: silence, as in ArduPilot). A
vehicle type without a mission of its own (`has_mission` False: a companion computer) serves no
type at all and answers UNSUPPORTED only to requests addressed to its own component, so a
ground station asking the whole system hears the flight controller alone and never a made-up
home (issue 27).
MAV_MISSION_TYPE_ALL in MISSION_CLEAR_ALL clears all three (the MAVLink spec's meaning; ArduPilot
answers UNSUPPORTED): DENIED if another node is uploading any of them, else one ACK with type ALL.
What the machines return is written out here: `Send` with `ctx.reply` on its channel, `Text` as
STATUSTEXT (on that channel, or every ground station), `PlanChanged` logged and MISSION_CURRENT
pushed. While an upload requests items on a link, that link's streams run x4 slower
(`Link.set_slow("mission", ...)`). The machines' timers (re-request after the uploader's
adaptive timeout, gcsd.vehicle.mission.rtt, at most `mission.retry_ms` plus the link's backlog and radio slowdown;
abort after 8 s) run from the node's send pass: `pending(channel, now, send)` ticks them and
returns their next deadline, so the channel task wakes in time. One RttTable serves the three
types, so a ground station's fence upload starts with what its mission upload measured. A
channel's backlog is its byte budget's deficit at its bandwidth (a full token bucket: nothing
queued; an empty one: 100 ms of traffic still in the radio).

Persistence: `<state_dir>/mission.waypoints`, `fence.waypoints`, `rally.waypoints` (QGC WPL 110),
written with gcsd.atomic (temporary file, fsync, rename, fsync of the directory), so a crash at
any moment leaves the previous plan or the new one. An upload's plan is written off the event
loop and its MISSION_ACK held until the file is durable (planwriter.py); a clear and an FTP
plan write are written before the plan is adopted. Read at start; a
file that cannot be read or is not a valid plan is logged (`mission_file_invalid`, with the
reason) and renamed to `<name>.waypoints.invalid`, never silently overwritten; that type starts
empty.

Also: MISSION_SET_CURRENT (pushes MISSION_CURRENT with the new seq; nothing on failure),
MAV_CMD_DO_SET_MISSION_CURRENT (DENIED out of range; param2 = 1 is passed on to the vehicle's
`current_changed(seq, reset_jumps)` hook), MISSION_CURRENT's content
(`current_message`), the `item_reached(seq)` hook the simulation calls (MISSION_ITEM_REACHED to
every ground station), and mission items with current = 2 / 3 (guided "fly to" / change
altitude), which are not uploads: they go to `guided_handler` (ERROR until a simulation sets one).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from pathlib import Path

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.config import MissionConfig
from gcsd.vehicle.mission import wpl
from gcsd.vehicle.mission.download import is_lossy
from gcsd.vehicle.mission.effects import Origin, PlanChanged, Send, Text
from gcsd.vehicle.mission.items import MissionItem, from_item_float, from_item_int
from gcsd.vehicle.mission.rtt import RttTable
from gcsd.vehicle.mission.stores import FenceStore, MissionStore, PlanStore, RallyStore
from gcsd.vehicle.mission.together import Written, write_together
from gcsd.vehicle.mission.transfer import MissionTransfer
from gcsd.vehicle.services import Incoming, Service
from gcsd.vehicle.services.commands import CommandRequest
from gcsd.vehicle.services.planwriter import PlanWriter
from gcsd.vehicle.sim.geo import deg_e7

log = structlog.get_logger("gcsd.vehicle.mission")

SLOW_REASON = "mission"
GUIDED_CURRENT = (2, 3)  # MISSION_ITEM.current: 2 guided "fly to", 3 change altitude
DEFAULT_MISSION_CONFIG = MissionConfig()


def home_item(state) -> MissionItem:
    """Item 0 as ArduPilot serves it: a NAV_WAYPOINT at home, absolute altitude."""
    return MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 0, 1, 0.0, 0.0, 0.0, 0.0,
                       deg_e7(state.home_lat), deg_e7(state.home_lon), float(state.home_alt_m))


class MissionService(Service):
    capabilities = (
        M.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | M.MAV_PROTOCOL_CAPABILITY_MISSION_INT
        | M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE | M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
    )

    def __init__(self, ctx, config: MissionConfig = DEFAULT_MISSION_CONFIG,
                 state_dir: Path | None = None) -> None:
        self.ctx = ctx
        self.state_dir = None if state_dir is None else Path(state_dir)
        self.writer = PlanWriter(ctx.errors, ctx.now)  # an upload's plan written off the loop
        self.mission = MissionStore(config.max_items, lambda: home_item(ctx.state), self._saver("mission"))
        self.fence = FenceStore(config.max_fence, self._saver("fence"))
        self.rally = RallyStore(config.max_rally, self._saver("rally"))
        stores: tuple[PlanStore, ...] = (self.mission, self.fence, self.rally)
        for store in stores:
            self._load(store)
        if ctx.state.has_home:
            self.mission.home_changed()
        retry_s = config.retry_ms / 1000.0
        self.rtt = RttTable(max_s=retry_s)  # starts at INITIAL_RTO_S, never beyond retry_ms
        # a vehicle without a mission of its own (a companion computer) serves none: every plan
        # is then an unsupported mission type (MISSION_ACK UNSUPPORTED to a request addressed to
        # this component, nothing to one for the whole system, None to read_plan)
        self.transfers = {
            s.mission_type: MissionTransfer(s, retry_s=retry_s, slowdown_s=self._slowdown_s,
                                            queued_s=self._queued_s, rtt=self.rtt, lossy=_lossy)
            for s in stores
        } if ctx.vehicle.has_mission else {}
        self.guided_handler: Callable[[MissionItem, int], bool] | None = None
        # the vehicle's hook for a new current item: (seq, reset jump counters and resume)
        self.current_changed: Callable[[int, bool], None] | None = None
        self.reached_seq: int | None = None
        self.complete = False
        self._slowed: set[int] = set()  # channel indices whose streams we slowed
        if not self.transfers:
            self.capabilities = 0  # AUTOPILOT_VERSION claims no mission protocol

    def commands(self):
        return {M.MAV_CMD_DO_SET_MISSION_CURRENT: self.do_set_mission_current}

    # --- upload ------------------------------------------------------------------------------
    def handle_MISSION_COUNT(self, inc: Incoming) -> None:
        t = self._transfer(inc)
        if t is not None:
            self._run(t.mission_count(self._origin(inc), inc.msg.count, inc.now))

    def handle_MISSION_WRITE_PARTIAL_LIST(self, inc: Incoming) -> None:
        t = self._transfer(inc)
        if t is not None:
            m = inc.msg
            self._run(t.mission_write_partial_list(self._origin(inc), m.start_index, m.end_index, inc.now))

    def handle_MISSION_ITEM_INT(self, inc: Incoming) -> None:
        self._item(inc, from_item_int(inc.msg), legacy=False)

    def handle_MISSION_ITEM(self, inc: Incoming) -> None:
        self._item(inc, from_item_float(inc.msg), legacy=True)

    def _item(self, inc: Incoming, item: MissionItem | int, legacy: bool) -> None:
        m = inc.msg
        if m.mission_type == M.MAV_MISSION_TYPE_MISSION and m.current in GUIDED_CURRENT:
            self._guided(inc, item, m.current)
            return
        t = self._transfer(inc)
        if t is None:
            return
        writer = self.writer
        writer.deferring = True  # the last item's plan is written off the loop (planwriter.py)
        try:
            outputs = t.mission_item(self._origin(inc), m.seq, item, legacy, inc.now)
        finally:
            writer.deferring = False
        if writer.deferred():
            self._update_slow()
            writer.hold(outputs, self._run)  # the ACK goes out once the plan is durable
        else:
            self._run(outputs)

    def handle_MISSION_ACK(self, inc: Incoming) -> None:
        t = self.transfers.get(inc.msg.mission_type)
        if t is not None:
            self._run(t.mission_ack(self._origin(inc), inc.now))

    # --- download ----------------------------------------------------------------------------
    def handle_MISSION_REQUEST_LIST(self, inc: Incoming) -> None:
        t = self._transfer(inc)
        if t is not None:
            self._run(t.mission_request_list(self._origin(inc), inc.now))

    def handle_MISSION_REQUEST_INT(self, inc: Incoming) -> None:
        t = self.transfers.get(inc.msg.mission_type)
        if t is not None:
            self._run(t.mission_request(self._origin(inc), inc.msg.seq, False, inc.now))

    def handle_MISSION_REQUEST(self, inc: Incoming) -> None:
        t = self.transfers.get(inc.msg.mission_type)
        if t is not None:
            self._run(t.mission_request(self._origin(inc), inc.msg.seq, True, inc.now))

    # --- clear -------------------------------------------------------------------------------
    def handle_MISSION_CLEAR_ALL(self, inc: Incoming) -> None:
        mission_type = inc.msg.mission_type
        origin = self._origin(inc)
        if mission_type != M.MAV_MISSION_TYPE_ALL or not self.transfers:
            t = self._transfer(inc)
            if t is not None:
                self._run(t.mission_clear_all(origin, inc.now))
            return
        if any(t.denies(origin) for t in self.transfers.values()):
            self._ack(inc, M.MAV_MISSION_DENIED)
            return
        result = M.MAV_MISSION_ACCEPTED
        for t in self.transfers.values():
            code, out = t.clear(origin)
            self._run(out)
            if result == M.MAV_MISSION_ACCEPTED:
                result = code
        self._ack(inc, result)

    # --- current item ------------------------------------------------------------------------
    def handle_MISSION_SET_CURRENT(self, inc: Incoming) -> None:
        if self._set_current(inc.msg.seq, False):
            self.ctx.link(inc.channel).push(M.MAVLINK_MSG_ID_MISSION_CURRENT)

    def do_set_mission_current(self, req: CommandRequest) -> int:
        if not math.isfinite(req.param1) or not 0 <= req.param1 < self.mission.count():
            return M.MAV_RESULT_DENIED
        if not self._set_current(int(req.param1), req.param2 == 1):
            return M.MAV_RESULT_FAILED
        self._push_current()
        return M.MAV_RESULT_ACCEPTED

    def _set_current(self, seq: int, reset_jumps: bool) -> bool:
        if not self.mission.set_current(seq):
            return False
        self.complete = False
        if self.current_changed is not None:
            self.current_changed(seq, reset_jumps)
        return True

    def current_message(self):
        """MISSION_CURRENT: the current item, the count without home, the mission's state."""
        ctx = self.ctx
        count = self.mission.count()
        auto = ctx.vehicle.mode_number("AUTO")
        in_auto = auto is not None and ctx.state.mode == auto
        if count <= 1:
            state = M.MISSION_STATE_NO_MISSION
        elif self.complete:
            state = M.MISSION_STATE_COMPLETE
        elif in_auto and ctx.state.armed:
            state = M.MISSION_STATE_ACTIVE
        else:
            state = M.MISSION_STATE_NOT_STARTED
        total = max(count - 1, 0)
        return M.MAVLink_mission_current_message(self.mission.current_seq, total, state, int(in_auto))

    def item_reached(self, seq: int) -> None:
        """The vehicle reached mission item `seq`: MISSION_ITEM_REACHED to every ground station."""
        self.reached_seq = seq
        if seq >= self.mission.count() - 1:
            self.complete = True
        msg = M.MAVLink_mission_item_reached_message(seq)
        for index in self.ctx.text_channels():
            self.ctx.reply(self.ctx.channels[index], msg)

    def home_changed(self) -> None:
        """Home was set: with no mission, the mission becomes home alone."""
        self.mission.home_changed()

    # --- whole plans (FTP's @MISSION/mission.dat, fence.dat, rally.dat; the HTTP .plan) -------
    def read_plan(self, mission_type: int) -> tuple[MissionItem, ...] | None:
        """The plan as a download serves it (None for an unknown type)."""
        t = self.transfers.get(mission_type)
        return None if t is None else t.store.items()

    def write_plan(self, mission_type: int, items) -> int:
        """Replace a whole plan with the checks of an upload; returns the MAV_MISSION_RESULT."""
        t = self.transfers.get(mission_type)
        if t is None:
            return M.MAV_MISSION_UNSUPPORTED
        result, out = t.write_plan(items, self.ctx.now())
        self._run(out)
        return result

    def write_plans(self, plans: dict[int, tuple[MissionItem, ...]]) -> Written:
        """Replace several plans (by mission type) all or none, each with the checks of an upload
        (gcsd.vehicle.mission.together); the refusal's reason is returned, not sent as text."""
        missing = [t for t in plans if t not in self.transfers]
        if missing:
            return Written(M.MAV_MISSION_UNSUPPORTED, missing[0], "no mission on this component")
        written = write_together((self.transfers[t], items) for t, items in plans.items())
        self._run(written.outputs)
        return written

    def shutdown(self, now: float) -> None:
        """A clean stop: uploads in progress are cancelled (their uploaders are told); plans were
        saved when they were adopted, so there is nothing to flush."""
        for t in self.transfers.values():
            self._run(t.cancel(now))

    # --- timers ------------------------------------------------------------------------------
    def pending(self, channel, now: float, send) -> float | None:
        """Called from the node's send pass: run the transfer timers; return the next deadline.

        A tick that queued a STATUSTEXT asks for another pass at once (`now`): the text queue
        was already run in this one (scheduler.py, "The pass").
        """
        again = False
        for t in self.transfers.values():
            out = t.tick(now)
            if out:
                self._run(out)
                again = True
        if again:
            return now
        deadlines = [d for t in self.transfers.values() if (d := t.next_deadline()) is not None]
        return min(deadlines) if deadlines else None

    # --- plumbing ----------------------------------------------------------------------------
    def _origin(self, inc: Incoming) -> Origin:
        return Origin(inc.frame.sysid, inc.frame.compid, inc.channel, inc.frame.version == 1)

    def _transfer(self, inc: Incoming) -> MissionTransfer | None:
        t = self.transfers.get(inc.msg.mission_type)
        if t is None and (self.ctx.vehicle.has_mission or inc.msg.target_component == self.ctx.compid):
            self._ack(inc, M.MAV_MISSION_UNSUPPORTED)  # a companion: only when asked by name
        return t

    def _ack(self, inc: Incoming, result: int) -> None:
        sysid, compid = inc.sender
        ack = M.MAVLink_mission_ack_message(sysid, compid, result, inc.msg.mission_type)
        self.ctx.reply(inc.channel, ack)

    def _guided(self, inc: Incoming, item: MissionItem | int, current: int) -> None:
        handler = self.guided_handler
        ok = not isinstance(item, int) and handler is not None and handler(item, current)
        self._ack(inc, M.MAV_MISSION_ACCEPTED if ok else M.MAV_MISSION_ERROR)

    def _run(self, outputs) -> None:
        ctx = self.ctx
        for out in outputs:
            if isinstance(out, Send):
                if not out.optional or out.channel.reply_goes_now():
                    ctx.reply(out.channel, out.msg)
            elif isinstance(out, Text):
                ctx.text(out.severity, out.text, None if out.channel is None else {out.channel.index})
            elif isinstance(out, PlanChanged):
                log.info("mission_plan_replaced", type=_TYPE_NAMES[out.mission_type], count=out.count)
                if out.mission_type == M.MAV_MISSION_TYPE_MISSION:
                    self.complete = False
                    self._push_current()
        self._update_slow()
        for t in self.transfers.values():
            if t.receiving:  # a request went out or is due: its deadline may be sooner than the
                self.ctx.wake(t.upload_channel)  # channel task's next pass (tens of ms on loopback)
            for channel in t.downloads.assist.channels():  # likewise a lossy download's next push
                self.ctx.wake(channel)

    def _push_current(self) -> None:
        self.ctx.push(M.MAVLINK_MSG_ID_MISSION_CURRENT)

    def _update_slow(self) -> None:
        uploading = {t.upload_channel.index for t in self.transfers.values() if t.receiving}
        if uploading == self._slowed:
            return
        for index in uploading ^ self._slowed:
            self.ctx.set_slow(self.ctx.channels[index], SLOW_REASON, index in uploading)
        self._slowed = uploading

    def _slowdown_s(self, channel) -> float:
        return self.ctx.link(channel).scheduler.slowdown_ms / 1000.0

    @staticmethod
    def _queued_s(channel) -> float:
        """Time to transmit what the link's byte budget says is still queued (0: unlimited)."""
        budget = channel.out.budget
        return 0.0 if budget is None else channel.budget_wait_s(int(budget.capacity))

    # --- files -------------------------------------------------------------------------------
    def _path(self, name: str) -> Path | None:
        return None if self.state_dir is None else self.state_dir / f"{name}.waypoints"

    def _saver(self, name: str):
        path = self._path(name)
        if path is None:
            return lambda items: None
        return lambda items: self.writer.save(path, wpl.dumps(items), getattr(self, name))

    def close(self) -> None:
        self.writer.close()

    def _load(self, store: PlanStore) -> None:
        path = self._path(store.name)
        if path is None or not path.exists():
            return
        try:
            reason = store.load(wpl.loads(path.read_text(encoding="utf-8")))
        except (OSError, UnicodeDecodeError, wpl.WplError) as exc:
            reason = str(exc)
        if reason is None:
            log.info("mission_plan_loaded", type=store.name, count=store.count(), path=str(path))
            return
        kept = path.with_name(path.name + ".invalid")
        try:
            os.replace(path, kept)
        except OSError as exc:
            kept = f"not renamed: {exc}"
        log.error("mission_file_invalid", type=store.name, path=str(path), reason=reason, kept_as=str(kept))


def _lossy(origin: Origin) -> bool:
    """Whether the requester's link loses frames (its sequence gaps, measured per peer)."""
    return is_lossy(*origin.channel.loss(origin.sysid, origin.compid))


_TYPE_NAMES = {M.MAV_MISSION_TYPE_MISSION: "mission", M.MAV_MISSION_TYPE_FENCE: "fence",
               M.MAV_MISSION_TYPE_RALLY: "rally"}
