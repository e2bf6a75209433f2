"""Message rates per link: REQUEST_DATA_STREAM, SET/GET_MESSAGE_INTERVAL, REQUEST_MESSAGE,
RADIO_STATUS slowdown. Behaviour as REFERENCE.md section 5:

- REQUEST_DATA_STREAM sets a stream's rate on the link it came in on (start_stop 0 -> 0 Hz),
  re-bucketing all its messages (overriding earlier SET_MESSAGE_INTERVALs for them). Ignored
  on `no_stream_override` channels. No reply.
- SET_MESSAGE_INTERVAL: param3 != 0 -> DENIED; an id neither ArduPilot maps
  (telemetry/ardupilot_ids.py) nor gcsd produces, or one this vehicle never sends (a companion's
  GPS_RAW_INT), -> DENIED; a mapped id without a producer is ACCEPTED and sends nothing, as an
  ArduPilot build without that feature; 0 -> default; -1 -> off;
  other negative -> DENIED; 1..999 us -> 1 ms; > 60 s -> 60 s; faster than the 3 ms cap ->
  DENIED with a STATUSTEXT. `no_stream_override` channels answer DENIED (the request is not
  honoured, and the ground station is told so).
- GET_MESSAGE_INTERVAL: an id SET_MESSAGE_INTERVAL refuses -> MESSAGE_INTERVAL(id, 0) + FAILED; not scheduled ->
  (id, -1) + ACCEPTED; else (id, interval_us) + ACCEPTED. REQUEST_MESSAGE(244, id) is the same.
- REQUEST_MESSAGE pushes one copy of the message on this link (FLIGHT_INFORMATION included, as
  ArduPilot); an id without a producer, or one this vehicle never sends -> FAILED.
- RADIO_STATUS txbuf adjusts the link's stream slowdown as ArduPilot's handle_radio_status.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.links.scheduler import MAX_INTERVAL_MS
from gcsd.vehicle.services import Incoming, Service
from gcsd.vehicle.services.commands import CommandRequest
from gcsd.vehicle.telemetry.ardupilot_ids import ARDUPILOT_MAPPED
from gcsd.wire.msgids import ACCEPTED, DENIED, FAILED
from gcsd.wire.streams import REQUEST_DATA_STREAM_IDS


class RatesService(Service):
    def __init__(self, ctx, producers) -> None:
        self.ctx = ctx
        self.producers = producers  # the ids that can be streamed or requested at all

    def _schedulable(self, msgid: int) -> bool:
        """SET/GET_MESSAGE_INTERVAL take it: ArduPilot maps it or gcsd produces it, and this
        vehicle sends it at all."""
        return (msgid in ARDUPILOT_MAPPED or msgid in self.producers) and self.ctx.vehicle.produces(msgid)

    def _requestable(self, msgid: int) -> bool:
        return msgid in self.producers and self.ctx.vehicle.produces(msgid)

    def commands(self):
        return {
            M.MAV_CMD_SET_MESSAGE_INTERVAL: self.set_message_interval,
            M.MAV_CMD_GET_MESSAGE_INTERVAL: self.get_message_interval,
            M.MAV_CMD_REQUEST_MESSAGE: self.request_message,
            M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self.request_autopilot_capabilities,
        }

    # --- messages --------------------------------------------------------------------------
    def handle_REQUEST_DATA_STREAM(self, inc: Incoming) -> None:
        if "no_stream_override" in inc.channel.config.options:
            return
        m = inc.msg
        if m.start_stop not in (0, 1):
            return
        streams = REQUEST_DATA_STREAM_IDS.get(m.req_stream_id)
        if streams is None:
            return
        rate = m.req_message_rate if m.start_stop == 1 else 0
        link = self.ctx.link(inc.channel)
        for stream in streams:
            link.set_stream_rate(stream, rate, inc.now)

    def handle_AUTOPILOT_VERSION_REQUEST(self, inc: Incoming) -> None:
        self.ctx.link(inc.channel).push(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)

    def handle_RADIO_STATUS(self, inc: Incoming) -> None:
        self.ctx.link(inc.channel).radio_txbuf(inc.msg.txbuf, inc.now)

    handle_RADIO = handle_RADIO_STATUS

    # --- commands --------------------------------------------------------------------------
    def set_message_interval(self, req: CommandRequest) -> int:
        msgid, interval_us = int(req.param1), req.param2
        if req.param3 != 0 or not self._schedulable(msgid):
            return DENIED
        channel = req.inc.channel
        if "no_stream_override" in channel.config.options:
            return DENIED
        link = self.ctx.link(channel)
        if interval_us == 0:
            link.reset_interval(msgid, req.inc.now)
            return ACCEPTED
        if interval_us == -1:
            link.set_interval(msgid, 0, req.inc.now)
            return ACCEPTED
        if interval_us < 0:
            return DENIED
        interval_ms = min(max(int(interval_us // 1000), 1), MAX_INTERVAL_MS)
        if interval_ms < self.ctx.min_interval_ms:
            self.ctx.text(
                M.MAV_SEVERITY_WARNING,
                f"Requested rate for message ID {msgid} too fast. Increase SCHED_LOOP_RATE",
                channels={channel.index},
            )
            return DENIED
        link.set_interval(msgid, interval_ms, req.inc.now)
        return ACCEPTED

    def get_message_interval(self, req: CommandRequest) -> int:
        return self._report_interval(req, int(req.param1))

    def _report_interval(self, req: CommandRequest, msgid: int) -> int:
        channel = req.inc.channel
        if msgid >= 65536 or msgid < 0 or not self._schedulable(msgid):
            self.ctx.reply(channel, M.MAVLink_message_interval_message(max(0, min(msgid, 65535)), 0))
            return FAILED
        interval_ms = self.ctx.link(channel).interval_ms(msgid)
        interval_us = -1 if not interval_ms else interval_ms * 1000
        self.ctx.reply(channel, M.MAVLink_message_interval_message(msgid, interval_us))
        return ACCEPTED

    def request_message(self, req: CommandRequest) -> int:
        msgid = int(req.param1)
        if msgid == M.MAVLINK_MSG_ID_MESSAGE_INTERVAL:
            return self._report_interval(req, int(req.param2))
        if not self._requestable(msgid):
            return FAILED
        self.ctx.link(req.inc.channel).push(msgid)
        return ACCEPTED

    def request_autopilot_capabilities(self, req: CommandRequest) -> int:
        if int(req.param1) != 1:
            return FAILED
        self.ctx.link(req.inc.channel).push(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        return ACCEPTED
