"""Vehicle control common to every vehicle type: arm/disarm, modes, home, banner, GCS presence.

ARM_DISARM (REFERENCE.md section 10): param1 1 arms (already armed -> ACCEPTED; param2 21196 or
2989 skips the checks; a failed check -> FAILED with "Arm: ..." / "PreArm: ..." text), param1 0
disarms (already disarmed -> ACCEPTED; 21196 forces it); anything else -> UNSUPPORTED. A mode
change is accepted for a mode number the vehicle type knows, and pushes a HEARTBEAT at once on
every link so ground stations see it without waiting.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.services import Incoming, Service
from gcsd.vehicle.services.commands import CommandRequest
from gcsd.wire.msgids import ACCEPTED, FAILED, UNSUPPORTED

FORCE_MAGIC = (21196, 2989)


class ControlService(Service):
    def __init__(self, ctx) -> None:
        self.ctx = ctx
        self.gcs_last_seen_s: float | None = None

    def commands(self):
        return {
            M.MAV_CMD_COMPONENT_ARM_DISARM: self.arm_disarm,
            M.MAV_CMD_DO_SET_MODE: self.do_set_mode,
            M.MAV_CMD_GET_HOME_POSITION: self.get_home_position,
            M.MAV_CMD_DO_SEND_BANNER: self.send_banner,
        }

    def handle_HEARTBEAT(self, inc: Incoming) -> None:
        if inc.frame.sysid == self.ctx.gcs_sysid:
            self.gcs_last_seen_s = inc.now

    def handle_SET_MODE(self, inc: Incoming) -> None:
        m = inc.msg
        if m.target_system == self.ctx.sysid and m.base_mode & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            self._set_mode(m.custom_mode)

    # --- commands --------------------------------------------------------------------------
    def arm_disarm(self, req: CommandRequest) -> int:
        forced = math.isfinite(req.param2) and int(req.param2) in FORCE_MAGIC  # NaN: not forced
        if req.param1 == 1:
            return self.arm(forced)
        if req.param1 == 0:
            return self._disarm(forced)
        return UNSUPPORTED

    def arm_by_rudder(self) -> bool:
        """ARMING_RUDDER's gesture (gcsd.vehicle.types.rc): arming with the same checks as a command."""
        return self.arm(False) == ACCEPTED

    def disarm_by_rudder(self) -> bool:
        return self._disarm(False) == ACCEPTED

    def arm(self, forced: bool = False) -> int:
        ctx = self.ctx
        state = ctx.state
        if state.armed:
            return ACCEPTED
        if not ctx.vehicle.can_arm:
            return UNSUPPORTED  # a companion computer: arming is the flight controller's business
        if not forced:
            failures = ctx.prearm_failures()
            if failures:
                for text in failures:
                    ctx.text(M.MAV_SEVERITY_CRITICAL, f"PreArm: {text}")
                return FAILED
            if not ctx.vehicle.can_arm_in(state.mode):
                ctx.text(M.MAV_SEVERITY_CRITICAL, "Arm: Mode not armable")
                return FAILED
        state.armed = True
        state.armed_at_s = ctx.now()
        ctx.text(M.MAV_SEVERITY_INFO, "Arming motors")
        ctx.push(M.MAVLINK_MSG_ID_HEARTBEAT)
        return ACCEPTED

    def _disarm(self, forced: bool) -> int:
        ctx = self.ctx
        state = ctx.state
        if not state.armed:
            return ACCEPTED
        if not forced and state.relative_alt_m > 0.5:
            ctx.text(M.MAV_SEVERITY_CRITICAL, "Disarm: vehicle is flying; use force to disarm")
            return FAILED
        state.armed = False
        ctx.text(M.MAV_SEVERITY_INFO, "Disarming motors")
        ctx.push(M.MAVLINK_MSG_ID_HEARTBEAT)
        return ACCEPTED

    def do_set_mode(self, req: CommandRequest) -> int:
        if not int(req.param1) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return UNSUPPORTED
        return ACCEPTED if self._set_mode(int(req.param2)) else FAILED

    def set_mode(self, number: int) -> bool:
        """Change mode as a ground station asked: False (with a STATUSTEXT) if refused."""
        return self._set_mode(number)

    def _set_mode(self, number: int) -> bool:
        ctx = self.ctx
        if number not in ctx.vehicle.modes:
            ctx.text(M.MAV_SEVERITY_WARNING, f"Mode change to {number} failed: unknown mode")
            return False
        refusal = ctx.autopilot.refuse_mode(number)  # the vehicle's own conditions (position, a mission...)
        if refusal is not None:
            ctx.text(M.MAV_SEVERITY_WARNING, f"Mode change to {ctx.vehicle.mode_name(number)} failed: {refusal}")
            return False
        if ctx.state.mode != number:
            ctx.state.mode = number
            ctx.push(M.MAVLINK_MSG_ID_HEARTBEAT)
        return True

    def get_home_position(self, req: CommandRequest) -> int:
        if not self.ctx.state.has_home:
            return FAILED
        link = self.ctx.link(req.inc.channel)
        link.push(M.MAVLINK_MSG_ID_HOME_POSITION)
        link.push(M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
        return ACCEPTED

    def send_banner(self, req: CommandRequest) -> int:
        self.ctx.banner()
        return ACCEPTED
