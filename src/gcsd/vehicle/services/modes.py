"""AVAILABLE_MODES (the standard-modes protocol), as ArduPilot's GCS_MAVLINK::send_available_mode.

MAV_CMD_REQUEST_MESSAGE with param1 435 asks for AVAILABLE_MODES: param2 0 for every mode, else
the mode at that index (1-based). ACCEPTED, then the message(s) on the requesting channel, after
the ACK (QGroundControl's StandardModes asks for index 1, learns number_modes, then asks for each
other index); an index beyond the list: DENIED. Every mode is reported as ArduPilot reports it:
MAV_STANDARD_MODE_NON_STANDARD, custom_mode = the mode number, properties 0, the mode's name; the
vehicle type's modes in mode-number order. MAVLink1 links cannot carry message 435: nothing is
sent there. Every other REQUEST_MESSAGE goes on to the rates service.

AVAILABLE_MODES is newer than the ardupilotmega dialect pymavlink ships, so it is built from
pymavlink's `all` dialect (the same wire format, packed by the link's own encoder).
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import all as ALL
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.services import Service
from gcsd.vehicle.services.commands import CommandRequest

AVAILABLE_MODES = ALL.MAVLINK_MSG_ID_AVAILABLE_MODES
OUTBOX_MAX = 64


class ModesService(Service):
    def __init__(self, ctx, rates) -> None:
        self.ctx = ctx
        self.rates = rates  # every REQUEST_MESSAGE but AVAILABLE_MODES goes on to it
        self.outbox: dict[int, list] = {}  # channel index -> AVAILABLE_MODES to send after the ACK

    def commands(self):
        return {M.MAV_CMD_REQUEST_MESSAGE: self.request_message}

    def modes(self) -> list[tuple[int, str]]:
        return sorted(self.ctx.vehicle.modes.items())

    def request_message(self, req: CommandRequest) -> int:
        if not math.isfinite(req.param1) or int(req.param1) != AVAILABLE_MODES:
            return self.rates.request_message(req)
        modes = self.modes()
        if not modes:
            return M.MAV_RESULT_DENIED
        index = int(req.param2) if math.isfinite(req.param2) else -1
        if index == 0:
            wanted = range(1, len(modes) + 1)
        elif 1 <= index <= len(modes):
            wanted = range(index, index + 1)
        else:
            return M.MAV_RESULT_DENIED
        box = self.outbox.setdefault(req.inc.channel.index, [])
        for i in wanted:
            number, name = modes[i - 1]
            box.append(ALL.MAVLink_available_modes_message(
                len(modes), i, ALL.MAV_STANDARD_MODE_NON_STANDARD, number, 0, name.encode()[:34]))
        del box[:-OUTBOX_MAX]
        self.ctx.wake(req.inc.channel)
        return M.MAV_RESULT_ACCEPTED

    def pending(self, channel, now: float, send) -> float | None:
        for msg in self.outbox.pop(channel.index, []):  # after the ACK, as replies: queued, never
            self.ctx.reply(channel, msg)  # dropped, while the link's byte budget is spent (outbox.py)
        return None
