"""Commands for the devices an ArduPilot vehicle may carry, answered as ArduPilot's libraries do.

gcsd simulates the vehicle, not its payload unless asked: with no `vehicle.camera`,
`vehicle.gimbal` or `can.buses` (the default) there is no camera, gimbal or CAN bus, and there
is never an ADS-B transponder or scripting engine. (With them, gimbal/, camera/ and can/ answer
those commands instead: compose.OVERRIDES.) ArduPilot SITL runs with the same libraries compiled in and no
device configured, and its answers (`../shared/ardupilot/*-probe.json`) follow from that; gcsd
gives the same answers for the same reason, and acts where it has the state:

| command | ArduPilot library | gcsd |
|---|---|---|
| DO_DIGICAM_CONFIGURE, DO_DIGICAM_CONTROL, DO_SET_CAM_TRIGG_DIST, IMAGE_STOP_CAPTURE | AP_Camera (no instance: nothing to do) | ACCEPTED |
| IMAGE_START_CAPTURE, VIDEO_START_CAPTURE, VIDEO_STOP_CAPTURE | AP_Camera (no instance to take it) | FAILED |
| SET_CAMERA_FOCUS, SET_CAMERA_SOURCE | AP_Camera (no such camera) | DENIED |
| DO_MOUNT_CONFIGURE, DO_MOUNT_CONTROL, DO_GIMBAL_MANAGER_CONFIGURE, _PITCHYAW | AP_Mount (no mount) | FAILED |
| DO_ADSB_OUT_IDENT | AP_ADSB (no transponder) | FAILED |
| CAN_FORWARD | AP_CANManager: param1 0 stops forwarding | ACCEPTED for 0 (nothing to stop), FAILED for a bus (none) |
| SCRIPTING | AP_Scripting (REPL removed; engine off with SCR_ENABLE 0) | DENIED |
| DEBUG_TRAP | param4 must be the 32451 magic | DENIED; with the magic UNSUPPORTED (no debugger to trap into) |
| DO_GRIPPER | AP_Gripper: FAILED unless GRIP_ENABLE | GRIP_ENABLE set: param2 0 release / 1 grab, ACCEPTED with ArduPilot's STATUSTEXT |
| DO_PARACHUTE | AP_Parachute: 0 disable, 1 enable, 2 release | CHUTE_ENABLED set/cleared; release needs it enabled and the vehicle flying (then disarmed: the motors stop), else STATUSTEXT why |
| AIRFRAME_CONFIGURATION | AP_LandingGear: param2 0 deploy, 1 retract | state kept, "LandingGear: DEPLOY" / "RETRACT" |
| DO_SET_SAFETY_SWITCH_STATE | the safety switch: 1 safe, 0 armable | kept; while safe, arming is refused (pre-arm "Safety switch") |
| BATTERY_RESET | AP_BattMonitor reset_remaining_mask(param1, param2) | bit 0 of the mask: battery 1's consumed charge set so that it shows param2 % |
| EXTERNAL_WIND_ESTIMATE | AHRS external wind | speed >= 0 and direction 0..360: ACCEPTED (kept as the estimate), else DENIED |
| SET_EKF_SOURCE_SET | AP_NavEKF_Source: 1..3 | ACCEPTED and kept, else DENIED |
| DO_FOLLOW | AP_Follow: param1 a system id | 1..255: FOLL_SYSID (when it exists), ACCEPTED; else DENIED |
| DO_SET_ROI_SYSID | the ROI follows a system; 0 clears it | 0: ROI none, ACCEPTED; another system: FAILED (the simulation does not point at other vehicles) |
| DO_AUX_FUNCTION | RC_Channel::run_aux_function(param1 function, param2 position 0 low / 1 middle / 2 high) | the functions below; another: FAILED ("Invalid channel option"); a position above 2: FAILED |
| START_RX_PAIR | RC receiver bind | ACCEPTED: RC input is RC_CHANNELS_OVERRIDE, which needs no pairing (as SITL's) |

Auxiliary functions gcsd runs (ArduPilot's numbers): 0 DO_NOTHING; mode switches 4 RTL, 16 AUTO,
18 LAND, 33 BRAKE, 42 SMART_RTL, 51 MANUAL, 52 ACRO, 55 GUIDED, 56 LOITER (high: that mode, when
the vehicle has it, else FAILED; low/middle: nothing, as there is no mode switch to fall back to);
11 FENCE (high enables, low disables); 81 DISARM (high); 153 ARM/DISARM (high arms with the
pre-arm checks, low disarms).

Vehicle types without one of these (a rover has no landing gear) map the command to
`vehicles.commands.unsupported` in their own command table, which wins over this one.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.services import Service
from gcsd.vehicle.services.commands import CommandRequest
from gcsd.wire.msgids import ACCEPTED, DENIED, FAILED, UNSUPPORTED

DEBUG_TRAP_MAGIC = 32451
AUX_MODES = {4: "RTL", 16: "AUTO", 18: "LAND", 33: "BRAKE", 42: "SMART_RTL", 51: "MANUAL", 52: "ACRO", 55: "GUIDED",
             56: "LOITER"}
AUX_NOTHING, AUX_FENCE, AUX_DISARM, AUX_ARMDISARM = 0, 11, 81, 153
LOW, MIDDLE, HIGH = 0, 1, 2
EXTERNAL_WIND_ESTIMATE = getattr(M, "MAV_CMD_EXTERNAL_WIND_ESTIMATE", 43004)  # newer than this pymavlink


def _accepted(req: CommandRequest) -> int:
    return ACCEPTED


def _failed(req: CommandRequest) -> int:
    return FAILED


def _denied(req: CommandRequest) -> int:
    return DENIED


class PeripheralService(Service):
    def __init__(self, ctx) -> None:
        self.ctx = ctx
        self.gear_deployed = True
        self.gripper_grabbed = False
        self.ekf_source_set = 1
        self.wind_estimate: tuple[float, float] | None = None

    def commands(self):
        table = {cmd: _accepted for cmd in (
            M.MAV_CMD_DO_DIGICAM_CONFIGURE, M.MAV_CMD_DO_DIGICAM_CONTROL, M.MAV_CMD_DO_SET_CAM_TRIGG_DIST,
            M.MAV_CMD_IMAGE_STOP_CAPTURE)}
        table.update({cmd: _failed for cmd in (
            M.MAV_CMD_IMAGE_START_CAPTURE, M.MAV_CMD_VIDEO_START_CAPTURE, M.MAV_CMD_VIDEO_STOP_CAPTURE,
            M.MAV_CMD_DO_MOUNT_CONFIGURE, M.MAV_CMD_DO_MOUNT_CONTROL, M.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE,
            M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, M.MAV_CMD_DO_ADSB_OUT_IDENT)})
        table.update({cmd: _denied for cmd in (
            M.MAV_CMD_SET_CAMERA_FOCUS, M.MAV_CMD_SET_CAMERA_SOURCE, M.MAV_CMD_SCRIPTING)})
        table.update({
            M.MAV_CMD_CAN_FORWARD: self.can_forward, M.MAV_CMD_DEBUG_TRAP: self.debug_trap,
            M.MAV_CMD_DO_GRIPPER: self.gripper, M.MAV_CMD_DO_PARACHUTE: self.parachute,
            M.MAV_CMD_AIRFRAME_CONFIGURATION: self.landing_gear,
            M.MAV_CMD_DO_SET_SAFETY_SWITCH_STATE: self.safety_switch, M.MAV_CMD_BATTERY_RESET: self.battery_reset,
            EXTERNAL_WIND_ESTIMATE: self.wind_estimate_cmd, M.MAV_CMD_SET_EKF_SOURCE_SET: self.ekf_source,
            M.MAV_CMD_DO_FOLLOW: self.follow, M.MAV_CMD_DO_SET_ROI_SYSID: self.roi_sysid,
            M.MAV_CMD_START_RX_PAIR: _accepted, M.MAV_CMD_DO_AUX_FUNCTION: self.aux_function,
        })
        return table

    def _param(self, name: str, default: float) -> float:
        params = self.ctx.params
        return float(params.get(name)) if name in params else default

    def can_forward(self, req: CommandRequest) -> int:
        return ACCEPTED if req.param1 == 0 else FAILED

    def debug_trap(self, req: CommandRequest) -> int:
        return UNSUPPORTED if req.param4 == DEBUG_TRAP_MAGIC else DENIED

    def gripper(self, req: CommandRequest) -> int:
        if not self._param("GRIP_ENABLE", 0):
            return FAILED
        action = round(req.param2) if math.isfinite(req.param2) else -1
        if action == M.GRIPPER_ACTION_RELEASE:
            self.gripper_grabbed = False
            self.ctx.text(M.MAV_SEVERITY_INFO, "Gripper load releasing")
        elif action == M.GRIPPER_ACTION_GRAB:
            self.gripper_grabbed = True
            self.ctx.text(M.MAV_SEVERITY_INFO, "Gripper load grabbing")
        else:
            return FAILED
        return ACCEPTED

    def parachute(self, req: CommandRequest) -> int:
        action = round(req.param1) if math.isfinite(req.param1) else -1
        if action in (M.PARACHUTE_DISABLE, M.PARACHUTE_ENABLE):
            if "CHUTE_ENABLED" in self.ctx.params:
                self.ctx.params.set("CHUTE_ENABLED", action, force=True)
            return ACCEPTED
        if action != M.PARACHUTE_RELEASE:
            return FAILED
        if not self._param("CHUTE_ENABLED", 0):
            self.ctx.text(M.MAV_SEVERITY_INFO, "Parachute: Not enabled")
        elif not self.ctx.state.armed or self.ctx.state.on_ground:
            self.ctx.text(M.MAV_SEVERITY_INFO, "Parachute: Landed")
        else:
            self.ctx.text(M.MAV_SEVERITY_CRITICAL, "Parachute: Released")
            self.ctx.autopilot.disarm("parachute released")
        return ACCEPTED

    def landing_gear(self, req: CommandRequest) -> int:
        position = round(req.param2) if math.isfinite(req.param2) else -1
        if position not in (0, 1):
            return FAILED
        self.gear_deployed = position == 0
        self.ctx.text(M.MAV_SEVERITY_INFO, "LandingGear: " + ("DEPLOY" if self.gear_deployed else "RETRACT"))
        return ACCEPTED

    def safety_switch(self, req: CommandRequest) -> int:
        state = round(req.param1) if math.isfinite(req.param1) else -1
        if state == M.SAFETY_SWITCH_STATE_SAFE:
            if self.ctx.state.armed:
                return DENIED
            self.ctx.state.safety_on = True
        elif state == M.SAFETY_SWITCH_STATE_DANGEROUS:
            self.ctx.state.safety_on = False
        else:
            return FAILED
        return ACCEPTED

    def battery_reset(self, req: CommandRequest) -> int:
        mask = int(req.param1) if math.isfinite(req.param1) and req.param1 >= 0 else 0
        percent = req.param2 if math.isfinite(req.param2) else -1.0
        if not 0 <= percent <= 100:
            return FAILED
        if mask & 1:
            s = self.ctx.state
            s.consumed_mah = s.capacity_mah * (1.0 - percent / 100.0)
        return ACCEPTED

    def wind_estimate_cmd(self, req: CommandRequest) -> int:
        speed, direction = req.param1, req.param3
        if not (math.isfinite(speed) and math.isfinite(direction)) or speed < 0 or not 0 <= direction <= 360:
            return DENIED
        self.wind_estimate = (speed, direction)
        return ACCEPTED

    def ekf_source(self, req: CommandRequest) -> int:
        source = round(req.param1) if math.isfinite(req.param1) else 0
        if not 1 <= source <= 3:
            return DENIED
        self.ekf_source_set = source
        return ACCEPTED

    def follow(self, req: CommandRequest) -> int:
        sysid = round(req.param1) if math.isfinite(req.param1) else 0
        if not 1 <= sysid <= 255:
            return DENIED
        if "FOLL_SYSID" in self.ctx.params:
            self.ctx.params.set("FOLL_SYSID", sysid, force=True)
        return ACCEPTED

    def roi_sysid(self, req: CommandRequest) -> int:
        if req.param1 == 0:
            self.ctx.autopilot.set_roi(None)
            return ACCEPTED
        return FAILED

    def aux_function(self, req: CommandRequest) -> int:
        function = round(req.param1) if math.isfinite(req.param1) else -1
        position = round(req.param2) if math.isfinite(req.param2) else -1
        if not LOW <= position <= HIGH:
            return FAILED
        ctx = self.ctx
        if function == AUX_NOTHING:
            return ACCEPTED
        if function in AUX_MODES:
            if position != HIGH:
                return ACCEPTED
            number = ctx.vehicle.mode_number(AUX_MODES[function])
            return ACCEPTED if number is not None and ctx.control.set_mode(number) else FAILED
        if function == AUX_FENCE and "FENCE_ENABLE" in ctx.params:
            if position != MIDDLE:
                ctx.params.set("FENCE_ENABLE", int(position == HIGH), force=True)
            return ACCEPTED
        if function == AUX_DISARM:
            if position == HIGH:
                ctx.autopilot.disarm("auxiliary switch")
            return ACCEPTED
        if function == AUX_ARMDISARM:
            if position == HIGH and not ctx.state.armed:
                return ctx.control.arm(forced=False)
            if position == LOW:
                ctx.autopilot.disarm("auxiliary switch")
            return ACCEPTED
        ctx.text(M.MAV_SEVERITY_INFO, f"Invalid channel option ({function})")
        return FAILED
