"""The mission-item transfer machine: one per mission type, pure, time passed in as `now`.

It takes decoded requests from an `Origin` (sysid, compid, the opaque channel they came on, and
whether that link speaks MAVLink1) and returns what to do (effects.py): `Send(channel, msg)`,
`Text(...)` and `PlanChanged` when the store's plan was replaced. `tick(now)` runs the timers and
`next_deadline()` says when it next needs to. It never touches a socket or a clock; the plan
is written by the saver its owner injects (MissionService), before the ACK is sent.

States and transitions (REFERENCE.md 7.1, with SPEC.md's improvements marked *):

    IDLE --MISSION_COUNT(n > 0) / WRITE_PARTIAL_LIST(start..end)--> RECEIVING(owner, channel)
    RECEIVING --item seq == next, not last--> RECEIVING (request next at once)
    RECEIVING --last item--> IDLE: the whole plan is checked, saved and adopted, ACK ACCEPTED;
              or ACK ERROR with the reason as STATUSTEXT and the old plan kept (*atomic upload)
    RECEIVING --item rejected by the store--> IDLE, ACK with that item's result, old plan kept
    RECEIVING --8 s without a valid item--> IDLE, "<Type> upload timeout" + OPERATION_CANCELLED
    RECEIVING --MISSION_COUNT / CLEAR_ALL / MISSION_ACK from the owner--> the upload is dropped
              silently (a MISSION_ACK from the owner is how MAVSDK cancels*) and the new request runs
    RECEIVING --cancel() (the daemon stops)--> IDLE, OPERATION_CANCELLED, old plan kept

While RECEIVING: the next item is requested with MISSION_REQUEST (msg 40, as ArduPilot does)
targeted at the owner on the channel the upload began on. No item within the retransmission
timeout sends the request again, without limit until the 8 s abort. *The timeout adapts (gcsd.vehicle.mission.rtt,
RFC 6298): the uploader's (channel, sysid, compid) has a round-trip estimate, sampled as the time
from a request sent once to the item that answers it (Karn's rule: no sample from a request sent
again), doubled on a timeout (at most x4); 250 ms before the first sample; never more than
`retry_s` (mission.retry_ms, ArduPilot's fixed 1 s). To it are added, when the request is sent, the
time the link needs to transmit what is queued ahead of it (`queued_s(channel)`: the byte budget's
backlog) and the link's RADIO_STATUS slowdown, as ArduPilot adds stream_slowdown_ms. So a loopback
ground station gets a lost item asked for again within tens of milliseconds, a 57 600 baud radio
only once the request and the item could have crossed it. Requests from any other
(sysid, compid) get DENIED (*ownership), items from the owner may come on any channel.

Result codes: fence/rally over a MAVLink1 link UNSUPPORTED ("Need mavlink2 for item transfer");
count above the store's limit NO_SPACE ("Only N items are supported"); an item with seq beyond
the expected one INVALID_SEQUENCE (the upload goes on); an item again for a seq already received
is ignored* (ArduPilot answers INVALID_SEQUENCE, which makes MAVSDK abandon the upload); an item
when nothing is being received ERROR, except the final item of the last completed upload from
the same node, which gets that upload's ACK again* (its first ACK was lost). *The ACK that ends
an upload goes out twice: MAVSDK and MAVProxy never resend their last item, so a lost final ACK
fails their whole upload (MAVSDK gives up 2.5 s later): measured, one MAVSDK upload in five
through 20 % loss failed that way with one copy. QGroundControl stops listening once it has
its ACK; MAVSDK's finished transfer ignores the copy.

Downloads are answered by `Downloads` (download.py: no transfer state, as in ArduPilot, with
repeated requests and lossy links looked after there); this machine only refuses them while
receiving: REQUEST_LIST and REQUEST_INT get DENIED then (a legacy REQUEST is still answered).
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission.download import Downloads
from gcsd.vehicle.mission.effects import Origin, Output, PlanChanged, Send, Text
from gcsd.vehicle.mission.items import MissionItem
from gcsd.vehicle.mission.rtt import INITIAL_RTO_S, RttEstimator, RttTable
from gcsd.vehicle.mission.stores import PlanStore

RETRY_S = 1.0
ABORT_S = 8.0
ACCEPTED, ERROR, DENIED = M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_ERROR, M.MAV_MISSION_DENIED
FINAL_ACK_COPIES = 2  # the ACK that ends an upload is sent twice
LEGACY_ITEM_TEXT = "got MISSION_ITEM; GCS should send MISSION_ITEM_INT"


@dataclass(slots=True)
class _Upload:
    owner: tuple[int, int]
    channel: Hashable
    start: int
    end: int  # last seq, inclusive
    partial: bool
    plan_count: int  # items in the plan once this upload is in
    next_seq: int
    last_item_s: float
    rtt: RttEstimator
    request_s: float = 0.0  # when the request for next_seq was last sent
    deadline_s: float = 0.0  # when to send it again
    repeated: bool = False  # the request for next_seq went out more than once (Karn: no sample)
    items: list[MissionItem] = field(default_factory=list)
    warned_legacy: bool = False


@dataclass(frozen=True, slots=True)
class _Finished:
    owner: tuple[int, int]
    seq: int
    result: int


class MissionTransfer:
    def __init__(self, store: PlanStore, retry_s: float = RETRY_S, abort_s: float = ABORT_S,
                 slowdown_s: Callable[[Hashable], float] = lambda channel: 0.0,
                 queued_s: Callable[[Hashable], float] = lambda channel: 0.0,
                 rtt: RttTable | None = None, lossy: Callable[[Origin], bool] = lambda origin: False) -> None:
        """`rtt`: the per-peer estimates, shared by the three types (a private table if None);
        `slowdown_s` / `queued_s`: a channel's radio slowdown and byte-budget backlog, seconds;
        `lossy`: whether the link a requester is on loses frames (download.py)."""
        self.downloads = Downloads(store, lossy)
        self.store = store
        self.retry_s = retry_s
        self.abort_s = abort_s
        self.slowdown_s = slowdown_s
        self.queued_s = queued_s
        self.rtt = rtt if rtt is not None else RttTable(initial_s=INITIAL_RTO_S, max_s=retry_s)
        self.mission_type = store.mission_type
        self._upload: _Upload | None = None
        self._finished: _Finished | None = None

    # --- what the adapter may ask ------------------------------------------------------------
    @property
    def receiving(self) -> bool:
        return self._upload is not None

    @property
    def upload_channel(self) -> Hashable | None:
        return None if self._upload is None else self._upload.channel

    @property
    def uploader(self) -> tuple[int, int] | None:
        return None if self._upload is None else self._upload.owner

    def next_deadline(self) -> float | None:
        up = self._upload
        pushes = self.downloads.next_deadline()
        if up is None:
            return pushes
        return min(up.deadline_s, up.last_item_s + self.abort_s, *([] if pushes is None else [pushes]))

    # --- upload ------------------------------------------------------------------------------
    def mission_count(self, origin: Origin, count: int, now: float) -> list[Output]:
        refused = self._refuse_upload(origin, deny_owner=False)
        if refused:
            return refused
        self._upload = None  # a new MISSION_COUNT from the owner replaces its upload
        self._finished = None
        if count > self.store.max_items:
            return self._no_space(origin)
        if count == 0:
            return self._clear_and_ack(origin)
        return self._start(origin, 0, count - 1, False, count, now)

    def mission_write_partial_list(self, origin: Origin, start: int, end: int, now: float) -> list[Output]:
        refused = self._refuse_upload(origin, deny_owner=True)
        if refused:
            return refused
        count = self.store.count()
        if start < 0 or end < start or start > count or end > count:
            return [Text(M.MAV_SEVERITY_WARNING, "Flight plan update rejected", origin.channel),
                    self._ack(origin, ERROR)]
        if end + 1 > self.store.max_items:
            return self._no_space(origin)
        self._finished = None
        return self._start(origin, start, end, True, max(count, end + 1), now)

    def mission_item(self, origin: Origin, seq: int, item: MissionItem | int, legacy: bool,
                     now: float) -> list[Output]:
        """An item (or the result its conversion failed with) from MISSION_ITEM(_INT)."""
        up = self._upload
        if up is None:
            done = self._finished
            if done is not None and done.owner == origin.node and done.seq == seq:
                return [self._ack(origin, done.result)]
            return [self._ack(origin, ERROR)]
        if origin.node != up.owner:
            return [self._ack(origin, DENIED)]
        if seq != up.next_seq:
            if up.start <= seq < up.next_seq:
                return []  # a duplicate of an item already in: our re-request crossed it
            return [self._ack(origin, M.MAV_MISSION_INVALID_SEQUENCE)]
        out: list[Output] = []
        if legacy and not up.warned_legacy:
            up.warned_legacy = True
            out.append(Text(M.MAV_SEVERITY_WARNING, LEGACY_ITEM_TEXT, up.channel))
        result = item if isinstance(item, int) else self.store.check_item(item, seq, up.plan_count)
        if result != ACCEPTED:
            self._upload = None
            return out + [self._ack_owner(up, result)]
        up.items.append(item)
        up.last_item_s = now
        if not up.repeated:
            up.rtt.sample(now - up.request_s)
        if seq == up.end:
            return out + self._complete(up)
        up.next_seq = seq + 1
        up.repeated = False
        return out + [self._request(up, now)]

    def mission_ack(self, origin: Origin, now: float) -> list[Output]:
        """A MISSION_ACK from the uploader ends its upload (cancelled); anything else is ignored."""
        if self._upload is not None and self._upload.owner == origin.node:
            self._upload = None
        else:
            self.downloads.finish(origin.node)  # a download's end
        return []

    # --- download (download.py) --------------------------------------------------------------
    def mission_request_list(self, origin: Origin, now: float) -> list[Output]:
        if self._upload is not None:
            return [self._ack(origin, DENIED)]
        return self.downloads.request_list(origin, now)

    def mission_request(self, origin: Origin, seq: int, legacy: bool, now: float) -> list[Output]:
        if self._upload is not None and not legacy:
            return [self._ack(origin, DENIED)]
        return self.downloads.request(origin, seq, legacy, now)

    # --- clear -------------------------------------------------------------------------------
    def denies(self, origin: Origin) -> bool:
        """True while another node is uploading this type."""
        return self._upload is not None and self._upload.owner != origin.node

    def mission_clear_all(self, origin: Origin, now: float) -> list[Output]:
        if self.denies(origin):
            return [self._ack(origin, DENIED)]
        return self._clear_and_ack(origin)

    def clear(self, origin: Origin) -> tuple[int, list[Output]]:
        """Clear for `origin` (not denied): the result and what to send besides the ACK."""
        self._upload = None
        self._finished = None
        if self.store.clear_refused():
            return ERROR, []
        try:
            self.store.replace(())
        except OSError as exc:
            return ERROR, [self.save_failed(exc)]
        return ACCEPTED, [PlanChanged(self.mission_type, self.store.count())]

    # --- whole plans from elsewhere (FTP @MISSION/*.dat, the HTTP .plan) ---------------------
    def check_write(self, items: tuple[MissionItem, ...]) -> tuple[int, str | None]:
        """Every check an upload makes, nothing changed: (ACCEPTED, None) or (result, why):
        DENIED while an upload is in progress, NO_SPACE above the limit, an item's own result,
        ERROR for a plan invalid as a whole."""
        if self._upload is not None:
            return DENIED, f"{self.store.label}: a ground station is uploading one now"
        if len(items) > self.store.max_items:
            return M.MAV_MISSION_NO_SPACE, self._limit_text()
        for seq, item in enumerate(items):
            result = self.store.check_item(item, seq, len(items))
            if result != ACCEPTED:
                return result, f"{self.store.label} item {seq}: {M.enums['MAV_MISSION_RESULT'][result].name}"
        reason = self.store.check_plan(items)
        return (ACCEPTED, None) if reason is None else (ERROR, reason)

    def write_plan(self, items, now: float) -> tuple[int, list[Output]]:
        """Replace the whole plan at once, with every check an upload makes (check_write); the
        reason of NO_SPACE or ERROR goes out as text, as does a save that failed (ERROR)."""
        items = tuple(items)
        result, why = self.check_write(items)
        if result != ACCEPTED:
            shown = result in (M.MAV_MISSION_NO_SPACE, ERROR)
            return result, [Text(M.MAV_SEVERITY_WARNING, why)] if shown else []
        try:
            self.store.replace(items)
        except OSError as exc:
            return ERROR, [self.save_failed(exc)]
        return ACCEPTED, self.written()

    def written(self) -> list[Output]:
        """The store's plan was replaced from elsewhere: no upload's final ACK to repeat now."""
        self._finished = None
        return [PlanChanged(self.mission_type, self.store.count())]

    def cancel(self, now: float) -> list[Output]:
        """The vehicle is stopping: an upload in progress ends with OPERATION_CANCELLED."""
        up = self._upload
        if up is None:
            return []
        self._upload = None
        return [self._ack_owner(up, M.MAV_MISSION_OPERATION_CANCELLED)]

    # --- time --------------------------------------------------------------------------------
    def tick(self, now: float) -> list[Output]:
        return self.downloads.tick(now) + self._tick_upload(now)

    def _tick_upload(self, now: float) -> list[Output]:
        up = self._upload
        if up is None:
            return []
        if now >= up.last_item_s + self.abort_s:
            self._upload = None
            return [Text(M.MAV_SEVERITY_WARNING, f"{self.store.label} upload timeout", up.channel),
                    self._ack_owner(up, M.MAV_MISSION_OPERATION_CANCELLED)]
        if now >= up.deadline_s:
            up.rtt.timed_out()
            up.repeated = True
            return [self._request(up, now)]
        return []

    # --- internals ---------------------------------------------------------------------------
    def _refuse_upload(self, origin: Origin, deny_owner: bool) -> list[Output]:
        if origin.mavlink1 and self.mission_type != M.MAV_MISSION_TYPE_MISSION:
            return [Text(M.MAV_SEVERITY_WARNING, "Need mavlink2 for item transfer", origin.channel),
                    self._ack(origin, M.MAV_MISSION_UNSUPPORTED)]
        if self._upload is not None and (deny_owner or self._upload.owner != origin.node):
            return [self._ack(origin, DENIED)]
        return []

    def _start(self, origin: Origin, start: int, end: int, partial: bool, plan_count: int,
               now: float) -> list[Output]:
        rtt = self.rtt.get((origin.channel, origin.node))
        up = _Upload(origin.node, origin.channel, start, end, partial, plan_count, start, now, rtt)
        self._upload = up
        return [self._request(up, now)]

    def _complete(self, up: _Upload) -> list[Output]:
        self._upload = None
        if up.partial:
            plan = list(self.store.stored())
            for seq, item in enumerate(up.items, up.start):
                if seq < len(plan):
                    plan[seq] = item
                else:
                    plan.append(item)
        else:
            plan = up.items
        out: list[Output] = []
        reason = self.store.check_plan(tuple(plan))
        if reason is not None:
            out.append(Text(M.MAV_SEVERITY_WARNING, reason))
            result = ERROR
        else:
            try:
                self.store.replace(tuple(plan))
            except OSError as exc:
                out.append(self.save_failed(exc))
                result = ERROR
            else:
                result = ACCEPTED
                out.append(PlanChanged(self.mission_type, self.store.count()))
                text = self.store.completed_text()
                if text:
                    out.append(Text(M.MAV_SEVERITY_INFO, text))
        self._finished = _Finished(up.owner, up.end, result)
        out += [self._ack_owner(up, result)] * FINAL_ACK_COPIES
        return out

    def _clear_and_ack(self, origin: Origin) -> list[Output]:
        result, out = self.clear(origin)
        return out + [self._ack(origin, result)]

    def _no_space(self, origin: Origin) -> list[Output]:
        return [Text(M.MAV_SEVERITY_WARNING, self._limit_text(), origin.channel),
                self._ack(origin, M.MAV_MISSION_NO_SPACE)]

    def save_failed(self, exc: OSError) -> Text:
        return Text(M.MAV_SEVERITY_ERROR, f"{self.store.label} not saved: {exc.strerror or exc}")

    def _request(self, up: _Upload, now: float) -> Send:
        """The request for up.next_seq, sent now: its re-request deadline is set here."""
        up.request_s = now
        behind_s = self.queued_s(up.channel) + self.slowdown_s(up.channel)
        up.deadline_s = now + up.rtt.timeout_s(behind_s)
        return Send(up.channel, M.MAVLink_mission_request_message(*up.owner, up.next_seq, self.mission_type))

    def _limit_text(self) -> str:
        return f"Only {self.store.max_items} items are supported"

    def _ack(self, origin: Origin, result: int) -> Send:
        return Send(origin.channel, M.MAVLink_mission_ack_message(*origin.node, result, self.mission_type))

    def _ack_owner(self, up: _Upload, result: int) -> Send:
        return Send(up.channel, M.MAVLink_mission_ack_message(*up.owner, result, self.mission_type))
