"""SETUP_SIGNING (REFERENCE.md section 9), safer than ArduPilot: the key is accepted only from a
frame that arrived signed with the current key, or on a channel marked `unsigned_ok` (a trusted
link); anything else is refused with a STATUSTEXT, so a hijacker on an open radio cannot
install its own key. Refused while armed ("ERROR: Won't setup signing when armed"), and the
refusal goes back on the channel it came from so the ground station sees why (QGC #14250).
An all-zero key turns signing off. The initial timestamp is assigned as ArduPilot assigns it,
bounded as a frame's timestamp is (see signing.py), so a later setup repairs a wrong one. No ACK
exists for this message."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.services import Incoming, Service


class SigningService(Service):
    def __init__(self, ctx, manager) -> None:
        self.ctx = ctx
        self.manager = manager

    def handle_SETUP_SIGNING(self, inc: Incoming) -> None:
        ctx = self.ctx
        here = {inc.channel.index}
        if inc.msg.target_system != ctx.sysid:
            return
        trusted = inc.channel.unsigned_ok or (inc.frame.signed and self.manager.signing.key is not None)
        if not trusted:
            ctx.text(M.MAV_SEVERITY_ERROR, "ERROR: signing setup needs a signed or unsigned_ok link", channels=here)
            return
        if ctx.state.armed:
            ctx.text(M.MAV_SEVERITY_ERROR, "ERROR: Won't setup signing when armed", channels=here)
            return
        key = bytes(inc.msg.secret_key)
        try:
            self.manager.apply_key(key, inc.msg.initial_timestamp, ctx.wall())
        except OSError:
            ctx.text(M.MAV_SEVERITY_ERROR, "ERROR: Failed to save signing key", channels=here)
            return
        state = "disabled" if self.manager.signing.key is None else "enabled"
        ctx.text(M.MAV_SEVERITY_INFO, f"Signing {state}", channels=here)
