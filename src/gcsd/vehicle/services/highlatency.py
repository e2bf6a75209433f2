"""HIGH_LATENCY2 links (REFERENCE.md section 11): MAV_CMD_CONTROL_HIGH_LATENCY.

A channel with the `high_latency` option is a satellite-class link: it carries no HEARTBEAT
and no SRn_ streams, only HIGH_LATENCY2 every 5 s (SET_MESSAGE_INTERVAL may change that) plus
replies; and every byte to it is discarded until a ground station sends CONTROL_HIGH_LATENCY
param1 1 (param1 0 silences it again; anything else: FAILED). On other links HIGH_LATENCY2 is
sent only when asked (REQUEST_MESSAGE, SET_MESSAGE_INTERVAL).
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.services import Service
from gcsd.vehicle.services.commands import CommandRequest


class HighLatencyService(Service):
    def __init__(self, ctx) -> None:
        self.ctx = ctx

    def commands(self):
        return {M.MAV_CMD_CONTROL_HIGH_LATENCY: self.control_high_latency}

    def control_high_latency(self, req: CommandRequest) -> int:
        if req.param1 not in (0, 1):
            return M.MAV_RESULT_FAILED
        for channel in self.ctx.channels:
            if "high_latency" in channel.config.options:
                channel.out.output_enabled = req.param1 == 1
                self.ctx.wake(channel)
        return M.MAV_RESULT_ACCEPTED
