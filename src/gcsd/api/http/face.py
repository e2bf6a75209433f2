"""The HTTP API's view of the daemon (routes.Api): the tree, the WebSocket hub, sending, vehicles.

Fed by two paths, each message counted once:
- `frame_seen(frame, wall_s)`, the daemon's frame tap (at the channel's wake-up time): every good frame received on any
  channel (the traffic gcsd routes, the ground stations, and what clients post, which comes in
  on the `http` channel); stored as the Frame, decoded only when read. A frame from one of our
  own vehicles (a loop between two links) is left out, as the router ignores it.
- `own(sysid, compid, seq, msg)`, the `http` channel's output (gcsd.api.http.local): our vehicles'
  telemetry at that link's stream rates and their replies to what came in on it.

Commands from gcsd's own routes are MAVLink too: the face posts them on the `http` channel from
the vehicle's ground station (SYSID_MYGCS, compid MAV_COMP_ID_MISSIONPLANNER) and waits for the
vehicle's answer on it (COMMAND_ACK, PARAM_VALUE) up to REPLY_TIMEOUT_S: the same checks, texts
and broadcasts as for a ground station. Missions go through the mission service's whole-plan
entry (the checks of an upload). At most MAX_WAITERS answers are awaited at once (503 beyond).
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.api.http.body import RequestFailed
from gcsd.api.http.hub import Hub
from gcsd.api.http.local import LocalChannel
from gcsd.api.http.plan import PlanError, from_plan, to_plan
from gcsd.api.http.tree import MessageTree
from gcsd.vehicle.params.store import to_type
from gcsd.vehicle.services.mission import home_item
from gcsd.wire.codec import Frame

REPLY_TIMEOUT_S = 3.0
MAX_WAITERS = 64
GCS_COMPID = M.MAV_COMP_ID_MISSIONPLANNER


class _Waiter:
    __slots__ = ("future", "match", "sysid")

    def __init__(self, sysid: int, match: Callable, future: asyncio.Future) -> None:
        self.sysid = sysid
        self.match = match
        self.future = future


class Face:
    def __init__(self, channel: LocalChannel, nodes, status: Callable[[], dict], errors, now: Callable[[], float],
                 wall: Callable[[], float], list_logs: Callable[[], list[dict]] = list) -> None:
        self.channel = channel
        self.tree = MessageTree()
        self.hub = Hub(channel.stats)  # a WebSocket frame dropped for a slow client: the channel's drops
        self._nodes = {n.sysid: n for n in nodes}
        self._local = frozenset((n.sysid, n.compid) for n in nodes)
        self._status = status
        self._errors = errors
        self._now = now
        self._wall = wall
        self._list_logs = list_logs
        self._waiters: list[_Waiter] = []
        channel.sink = self.own

    # --- the two feeds ---------------------------------------------------------------------
    def frame_seen(self, frame: Frame, wall_s: float) -> None:
        if not frame.known or (frame.sysid, frame.compid) in self._local:
            return  # our own frames come back only through a loop: the http channel has them
        name = frame.name
        self.tree.update(frame.sysid, frame.compid, name, frame, wall_s)
        if self.hub.subscribers:
            self.hub.publish(frame.sysid, frame.compid, frame.seq, name, frame)

    def own(self, sysid: int, compid: int, seq: int, msg) -> None:
        name = msg.get_type()
        self.tree.update(sysid, compid, name, msg, self._wall())
        if self.hub.subscribers:
            self.hub.publish(sysid, compid, seq, name, msg)
        if self._waiters:
            for waiter in list(self._waiters):
                if waiter.sysid == sysid and not waiter.future.done() and waiter.match(msg):
                    waiter.future.set_result(msg)

    # --- routes.Api ------------------------------------------------------------------------
    def status(self) -> dict:
        status = self._status()
        status["http"] = {"websocket_clients": len(self.hub.subscribers), "websocket_frames": self.hub.frames_sent}
        return status

    def post(self, header, msg) -> None:
        self.channel.inject(header.system_id, header.component_id, msg, self._now())

    def vehicle(self, sysid: int):
        node = self._nodes.get(sysid)
        return None if node is None else VehicleFace(self, node)

    def failed(self, component: str) -> None:
        self._errors.failed(component, self._now())

    def logs(self) -> list[dict]:
        """The flight logs of every vehicle (gcsd.payloads.logs.listing: sysid, id, name, size, time_utc)."""
        return [{k: v for k, v in e.items() if k != "path"} for e in self._list_logs()]

    def log_file(self, log_id: str, sysid: int | None = None) -> Path | None:
        if not (log_id.isascii() and log_id.isdigit()):
            return None
        for e in self._list_logs():
            if e["id"] == int(log_id) and (sysid is None or e["sysid"] == sysid):
                return Path(e["path"])
        return None

    # --- asking a vehicle ------------------------------------------------------------------
    async def ask(self, node, msg, match: Callable) -> object:
        """Post `msg` from the vehicle's ground station on the http channel; the first message
        from the vehicle that `match`es, or RequestFailed(504)."""
        if len(self._waiters) >= MAX_WAITERS:
            raise RequestFailed(503, "too many requests waiting for a vehicle; try again")
        waiter = _Waiter(node.sysid, match, asyncio.get_running_loop().create_future())
        self._waiters.append(waiter)
        try:
            self.channel.inject(node.gcs_sysid, GCS_COMPID, msg, self._now())
            return await asyncio.wait_for(waiter.future, REPLY_TIMEOUT_S)
        except TimeoutError:
            raise RequestFailed(504, f"no answer from vehicle {node.sysid} within {REPLY_TIMEOUT_S:g} s") from None
        finally:
            self._waiters.remove(waiter)


class VehicleFace:
    """routes.Vehicle for one of our vehicles."""

    def __init__(self, face: Face, node) -> None:
        self.face = face
        self.node = node

    def parameters(self) -> dict[str, float]:
        return {e.name: e.value for e in self.node.params.entries()}

    def parameter(self, name: str) -> dict | None:
        entry = self.node.params.entry_by_name(name)
        if entry is None:
            return None
        return {"name": entry.name, "value": entry.value, "type": M.enums["MAV_PARAM_TYPE"][entry.ptype].name}

    async def set_parameter(self, name: str, value: float) -> dict:
        entry = self.node.params.entry_by_name(name)
        msg = M.MAVLink_param_set_message(self.node.sysid, self.node.compid, name.encode(), value, entry.ptype)
        await self.face.ask(self.node, msg, lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == name)
        now = self.parameter(name)
        wanted = to_type(entry.ptype, value)
        if not math.isclose(float(now["value"]), float(wanted), rel_tol=1e-6, abs_tol=1e-6):
            d = self.node.params.definition(name)
            why = "read-only" if d.read_only else "refused by the vehicle"
            raise RequestFailed(422, f"{name}: {value:g} refused ({why}); it is {now['value']}")
        return now

    def mission(self) -> dict:
        plans = self.node.plans
        items = plans.read_plan(M.MAV_MISSION_TYPE_MISSION) or ()
        home = home_item(self.node.state)
        return to_plan(tuple(items) if items else (home,), home, self.node.vehicle.mav_type,
                       plans.read_plan(M.MAV_MISSION_TYPE_FENCE), plans.read_plan(M.MAV_MISSION_TYPE_RALLY))

    def put_mission(self, document: object) -> dict:
        """The plan's mission, fence and rally, all or none (PlanError / RequestFailed if none)."""
        plan = from_plan(document)
        writes = {M.MAV_MISSION_TYPE_MISSION: (home_item(self.node.state), *plan.mission) if plan.mission else ()}
        if plan.fence is not None:
            writes[M.MAV_MISSION_TYPE_FENCE] = plan.fence
        if plan.rally is not None:
            writes[M.MAV_MISSION_TYPE_RALLY] = plan.rally
        written = self.node.plans.write_plans(writes)
        if written.result != M.MAV_MISSION_ACCEPTED:
            raise _refusal(written)
        counts = {"items": len(plan.mission)}
        counts.update({k: len(v) for k, v in (("fence", plan.fence), ("rally", plan.rally)) if v is not None})
        return counts

    def mode_names(self) -> list[str]:
        return list(self.node.vehicle.modes.values())

    async def set_mode(self, name: str) -> None:
        number = {v: k for k, v in self.node.vehicle.modes.items()}[name]
        await self._command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, number)

    async def arm(self, armed: bool) -> None:
        await self._command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0 if armed else 0.0)

    async def _command(self, command: int, param1: float = 0.0, param2: float = 0.0) -> None:
        node = self.node
        msg = M.MAVLink_command_long_message(node.sysid, node.compid, command, 0, param1, param2, 0, 0, 0, 0, 0)
        ack = await self.face.ask(node, msg, lambda m: m.get_type() == "COMMAND_ACK" and m.command == command)
        if ack.result != M.MAV_RESULT_ACCEPTED:
            raise RequestFailed(409, f"{M.enums['MAV_CMD'][command].name}: {M.enums['MAV_RESULT'][ack.result].name}")


_PART = {M.MAV_MISSION_TYPE_MISSION: ("mission", "mission.max_items, home included"),
         M.MAV_MISSION_TYPE_FENCE: ("geoFence", "mission.max_fence: polygon vertices, circles, return point"),
         M.MAV_MISSION_TYPE_RALLY: ("rallyPoints", "mission.max_rally")}


def _refusal(written) -> Exception:
    """A refused write as the HTTP answer: 409 while a ground station uploads, else 422."""
    part, limit_key = _PART[written.refused_type]
    if written.result == M.MAV_MISSION_DENIED:
        return RequestFailed(409, f"{part}: {written.reason}; nothing changed, try again")
    if written.result == M.MAV_MISSION_NO_SPACE:
        return PlanError(f"{part}: too many items for the vehicle, at most {written.limit} ({limit_key}); "
                         "nothing changed")
    home = " (item 0 is home)" if written.refused_type == M.MAV_MISSION_TYPE_MISSION else ""
    return PlanError(f"{part} refused, nothing changed: {written.reason}{home}")
