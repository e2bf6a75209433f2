"""COMMAND_LONG and COMMAND_INT: one dispatch table, exactly one COMMAND_ACK per command.

COMMAND_LONG is turned into the same CommandRequest as COMMAND_INT (frame
GLOBAL_RELATIVE_ALT; x/y are params 5/6, scaled by 1e7 for the commands that carry a location),
as ArduPilot does (a NaN latitude or longitude becomes 0 when both are NaN, "not given"; one
NaN alone stays NaN and is refused). A handler returns a MAV_RESULT; the ACK (progress 0,
targeted at the sender) is sent after the handler, so whatever the handler sends
(MESSAGE_INTERVAL) precedes it. Unknown commands get UNSUPPORTED; before a handler runs, the
parameters pass the edge check of `command_rules` (NaN, infinity, out-of-range values and bad
positions refused with DENIED or FAILED, unused parameters zeroed), so no handler sees a value
it cannot honour; a handler that raises gets FAILED and the error is logged; nothing is
de-duplicated by `confirmation` (a resent command is executed again, as in ArduPilot).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.services import Incoming, Service
from gcsd.vehicle.services.command_rules import RULES, STRICT, check

log = structlog.get_logger("gcsd.commands")

LOCATION_COMMANDS = frozenset({
    M.MAV_CMD_DO_SET_HOME, M.MAV_CMD_DO_SET_ROI, M.MAV_CMD_DO_SET_ROI_LOCATION, M.MAV_CMD_DO_REPOSITION,
    M.MAV_CMD_EXTERNAL_POSITION_ESTIMATE, getattr(M, "MAV_CMD_DO_SET_GLOBAL_ORIGIN", 611),
})
IMPLIED_FRAME = {
    M.MAV_CMD_DO_SET_HOME: M.MAV_FRAME_GLOBAL,
    M.MAV_CMD_DO_SET_ROI: M.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    M.MAV_CMD_DO_SET_ROI_LOCATION: M.MAV_FRAME_GLOBAL_RELATIVE_ALT,
}


@dataclass(frozen=True, slots=True)
class CommandRequest:
    command: int
    params: tuple[float, float, float, float]  # param1..param4
    x: float  # param5 (lat degE7 for location commands)
    y: float  # param6
    z: float  # param7
    frame: int
    is_int: bool
    inc: Incoming

    @property
    def param1(self) -> float:
        return self.params[0]

    @property
    def param2(self) -> float:
        return self.params[1]

    @property
    def param3(self) -> float:
        return self.params[2]

    @property
    def param4(self) -> float:
        return self.params[3]


def _scale_e7(v: float) -> float:
    """Degrees to degE7; NaN and infinity stay as they are (for the edge check to refuse)."""
    return v * 1e7 if not math.isfinite(v) else int(v * 1e7)


class CommandService(Service):
    capabilities = M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT

    def __init__(self, ctx, table: dict[int, Callable[[CommandRequest], int]]) -> None:
        self.ctx = ctx
        self.table = table
        self.unsupported = 0
        self.refused = 0  # commands refused by the edge check
        self.components: dict[int, dict[int, Callable[[CommandRequest], int]]] = {}  # another local compid's table

    def add_component(self, compid: int, table: dict[int, Callable[[CommandRequest], int]]) -> None:
        """A local component of this system with its own commands (the camera, compid 100): commands
        addressed to it run from its table, and its ACKs come from it."""
        self.components[compid] = table

    def counters(self) -> dict[str, int]:
        return {"commands_unsupported": self.unsupported, "commands_refused": self.refused}

    def handle_COMMAND_LONG(self, inc: Incoming) -> None:
        m = inc.msg
        cmd = m.command
        x, y = m.param5, m.param6
        frame = M.MAV_FRAME_GLOBAL_RELATIVE_ALT
        if cmd in LOCATION_COMMANDS:
            if cmd not in IMPLIED_FRAME:
                self._ack(inc, cmd, M.MAV_RESULT_UNSUPPORTED)  # needs COMMAND_INT to say its frame
                return
            frame = IMPLIED_FRAME[cmd]
            if math.isnan(x) and math.isnan(y):
                x = y = 0.0  # neither given: ArduPilot's 0, 0 ("here" / "none")
            x, y = _scale_e7(x), _scale_e7(y)
        self._run(CommandRequest(cmd, (m.param1, m.param2, m.param3, m.param4), x, y, m.param7, frame, False, inc))

    def handle_COMMAND_INT(self, inc: Incoming) -> None:
        m = inc.msg
        self._run(CommandRequest(m.command, (m.param1, m.param2, m.param3, m.param4), m.x, m.y, m.z, m.frame, True, inc))

    def _run(self, req: CommandRequest) -> None:
        compid = req.inc.frame.target_component
        table = self.components.get(compid)
        if table is None:
            table, compid = self.table, self.ctx.compid
        handler = table.get(req.command)
        if handler is None:
            self.unsupported += 1
            self._ack(req.inc, req.command, M.MAV_RESULT_UNSUPPORTED, compid)
            return
        checked = check(RULES.get(req.command, STRICT), (*req.params, req.x, req.y, req.z), req.frame)
        if isinstance(checked, int):
            self.refused += 1
            self._ack(req.inc, req.command, checked, compid)
            return
        p1, p2, p3, p4, x, y, z = checked
        req = replace(req, params=(p1, p2, p3, p4), x=x, y=y, z=z)
        result = M.MAV_RESULT_FAILED  # what the ground station hears if the handler raises
        with self.ctx.errors.guard(f"command:{req.command}", req.inc.now, channel=req.inc.channel.name,
                                    sysid=req.inc.frame.sysid):
            result = handler(req)
        self._ack(req.inc, req.command, result, compid)

    def _ack(self, inc: Incoming, command: int, result: int, from_compid: int | None = None) -> None:
        sysid, compid = inc.sender
        ack = M.MAVLink_command_ack_message(command, result, 0, 0, sysid, compid)
        if from_compid is None or from_compid == self.ctx.compid:
            self.ctx.reply(inc.channel, ack)
        else:
            inc.channel.send_message(ack, self.ctx.sysid, from_compid)
