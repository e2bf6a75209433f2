"""TIMESYNC: a request (tc1 = 0) is answered at once on the same link with tc1 = our receive
time in ns and ts1 echoed; responses are not needed by gcsd and are ignored."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.services import Incoming, Service


class TimesyncService(Service):
    def __init__(self, ctx) -> None:
        self.ctx = ctx

    def handle_TIMESYNC(self, inc: Incoming) -> None:
        if inc.msg.tc1 != 0:
            return
        now_ns = self.ctx.time_usec(inc.now) * 1000
        self.ctx.reply(inc.channel, M.MAVLink_timesync_message(now_ns, inc.msg.ts1))
