"""The gimbal manager on the autopilot component: MAVLink in, the `Mount` core, MAVLink out.

Commands (MAV_RESULT as ArduPilot 4.6 with a mount): DO_GIMBAL_MANAGER_PITCHYAW (x = flags,
z = gimbal device id), DO_GIMBAL_MANAGER_CONFIGURE (p1/p2 sysid/compid, z = device id),
DO_MOUNT_CONTROL (z = mode), DO_MOUNT_CONFIGURE (p1 = mode), DO_SET_ROI_SYSID (p1 = the system:
ACCEPTED). DO_SET_ROI_LOCATION / DO_SET_ROI / DO_SET_ROI_NONE and the mission's ROI items reach
the mount through the autopilot's `mount_roi` hook (Copter's AutoYaw::set_roi: a gimbal that
can pan points at the location; the vehicle keeps its own heading). Messages:
GIMBAL_MANAGER_SET_PITCHYAW (radians, as the command in degrees), GIMBAL_MANAGER_SET_ATTITUDE,
and, through a tap on every accepted frame, GLOBAL_POSITION_INT from the system DO_SET_ROI_SYSID
points at (as ArduPilot's mount reads it from any link). Values that are not finite where a
number is needed are ignored (messages) or refused at the edge (commands).

The mount is brought up to `now` (`sync`) whenever anything reads or changes it: a command, a
message, a telemetry producer (gimbal/telemetry.py), a send pass; so its slew and a pointed
target follow the vehicle however often it is asked. A change of primary control pushes
GIMBAL_MANAGER_STATUS on every link at once; warnings go out as STATUSTEXT.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.payloads.gimbal.mount import Mount, Pose
from gcsd.payloads.gimbal.params import NAMES, mount_params
from gcsd.vehicle.services import Incoming, Service
from gcsd.vehicle.services.commands import CommandRequest

MSG_ID_STATUS = M.MAVLINK_MSG_ID_GIMBAL_MANAGER_STATUS


class GimbalService(Service):
    def __init__(self, ctx, now: float) -> None:
        self.ctx = ctx
        self.mount = Mount(mount_params(ctx.params.get), now)
        for name in NAMES:
            ctx.params.on_change(name, self._params_changed)

    def _params_changed(self, _name, _value) -> None:
        self.mount.set_params(mount_params(self.ctx.params.get))

    def pose(self) -> Pose:
        s = self.ctx.state
        home = (s.home_lat, s.home_lon, s.home_alt_m) if s.has_home else None
        return Pose(s.lat, s.lon, s.alt_amsl_m, s.yaw_rad, home)

    def sync(self, now: float) -> Mount:
        """The mount, stepped to `now`; its warnings sent, a control change pushed."""
        mount = self.mount
        mount.step(now, self.pose())
        for text in mount.take_texts():
            self.ctx.text(M.MAV_SEVERITY_WARNING, text)
        if mount.status_changed:
            mount.status_changed = False
            self.ctx.push(MSG_ID_STATUS)
        return mount

    # --- commands ------------------------------------------------------------------------------
    def commands(self):
        return {
            M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW: self.pitchyaw,
            M.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE: self.configure,
            M.MAV_CMD_DO_MOUNT_CONTROL: self.mount_control,
            M.MAV_CMD_DO_MOUNT_CONFIGURE: self.mount_configure,
            M.MAV_CMD_DO_SET_ROI_SYSID: self.roi_sysid,
        }

    def pitchyaw(self, req: CommandRequest) -> int:
        mount = self.sync(req.inc.now)
        return mount.pitchyaw(int(req.x), req.param1, req.param2, req.param3, req.param4, req.z)

    def configure(self, req: CommandRequest) -> int:
        result = self.mount.configure(req.param1, req.param2, req.inc.sender, req.z)
        self.sync(req.inc.now)  # pushes GIMBAL_MANAGER_STATUS when control changed
        return result

    def mount_control(self, req: CommandRequest) -> int:
        mount = self.sync(req.inc.now)
        return mount.mount_control(req.param1, req.param2, req.param3, req.param4, int(req.x), int(req.y), req.z,
                                   self.ctx.state.home_alt_m, req.inc.now)

    def mount_configure(self, req: CommandRequest) -> int:
        return self.sync(req.inc.now).mount_configure(req.param1)

    def roi_sysid(self, req: CommandRequest) -> int:
        self.sync(req.inc.now).set_target_sysid(int(req.param1))
        return M.MAV_RESULT_ACCEPTED

    def roi(self, location: tuple[float, float, float] | None) -> bool:
        """The autopilot's ROI (lat, lon, alt AMSL; None: none): True when the gimbal takes it."""
        if not self.mount.params.has_pan:
            return False  # the vehicle has to turn to point the camera
        self.sync(self.ctx.now()).set_roi(location)
        return True

    # --- messages ------------------------------------------------------------------------------
    def handle_GIMBAL_MANAGER_SET_PITCHYAW(self, inc: Incoming) -> None:
        m = inc.msg
        values = (m.pitch, m.yaw, m.pitch_rate, m.yaw_rate)
        if any(math.isinf(v) for v in values):
            return
        self.sync(inc.now).pitchyaw(m.flags, *(math.degrees(v) for v in values), m.gimbal_device_id)

    def handle_GIMBAL_MANAGER_SET_ATTITUDE(self, inc: Incoming) -> None:
        m = inc.msg
        rates = (m.angular_velocity_x, m.angular_velocity_y, m.angular_velocity_z)
        if any(math.isinf(v) for v in (*m.q, *rates)):
            return
        self.sync(inc.now).set_attitude(m.flags, list(m.q), rates, m.gimbal_device_id)

    def tap(self, channel, frame, now: float) -> None:
        """Every accepted frame (compose registers it): the ROI_SYSID target's GLOBAL_POSITION_INT."""
        if frame.msgid == M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT and frame.sysid == self.mount.target_sysid:
            m = frame.msg
            self.mount.target_position(frame.sysid, m.lat / 1e7, m.lon / 1e7, m.alt / 1000.0)

    def pending(self, channel, now: float, send) -> float | None:
        self.sync(now)
        return None
