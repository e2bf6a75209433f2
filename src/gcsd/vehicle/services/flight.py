"""Flying commands and guided-mode messages: the thin layer between MAVLink and the autopilot.

Commands (REFERENCE.md section 10; COMMAND_LONG and COMMAND_INT alike): NAV_RETURN_TO_LAUNCH,
NAV_LAND, NAV_LOITER_UNLIM (switch to RTL, LAND, LOITER: UNSUPPORTED for a vehicle without
that mode), MISSION_START (param1 first item), DO_REPOSITION (COMMAND_INT: a guided target;
param2 bit 0 switches to GUIDED first, else DENIED outside guided), DO_CHANGE_SPEED (param2
m/s), DO_CHANGE_ALTITUDE, DO_SET_HOME (param1 1: here), DO_SET_ROI / DO_SET_ROI_LOCATION /
DO_SET_ROI_NONE, CONDITION_YAW, DO_PAUSE_CONTINUE, DO_SET_SERVO, DO_REPEAT_SERVO,
DO_SET_RELAY, DO_REPEAT_RELAY, DO_FENCE_ENABLE, DO_FLIGHTTERMINATION, DO_JUMP_TAG (to the mission's JUMP_TAG item
with that tag). The vehicle type adds
its own (takeoff, motor test...). A command the autopilot cannot do now gets FAILED.

Messages: SET_POSITION_TARGET_GLOBAL_INT and SET_POSITION_TARGET_LOCAL_NED (positions or
velocities by type_mask, in GUIDED only; a target in a frame it does not take, or with a NaN or
infinite value in a field its type_mask uses, is dropped whole and the old target kept); RC_CHANNELS_OVERRIDE and MANUAL_CONTROL only from
the GCS sysid (SYSID_MYGCS), as ArduPilot; GLOBAL_POSITION_INT from other systems feeds an
antenna tracker's target.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.autopilot.settings import Behaviour
from gcsd.vehicle.mission.items import GLOBAL_FRAMES
from gcsd.vehicle.services import Incoming, Service
from gcsd.vehicle.services.commands import CommandRequest
from gcsd.vehicle.sim.geo import offset
from gcsd.vehicle.types.rc import mapped_channel
from gcsd.wire.msgids import ACCEPTED, DENIED, FAILED, UNSUPPORTED

RELATIVE_FRAMES = frozenset({
    M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, M.MAV_FRAME_GLOBAL_TERRAIN_ALT,
    M.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT,
})
POSITION_IGNORED = 0b111
VELOCITY_IGNORED = 0b111000
YAW_IGNORED = 1024
YAW_RATE_IGNORED = 2048
RC_IGNORE = 65535
# SET_POSITION_TARGET_* fields in type_mask bit order (bit n set: field n ignored); bit 9 is a flag
LOCAL_FIELDS = ("x", "y", "z", "vx", "vy", "vz", "afx", "afy", "afz")
LOCAL_TARGET_FRAMES = frozenset({M.MAV_FRAME_LOCAL_NED, M.MAV_FRAME_LOCAL_OFFSET_NED, M.MAV_FRAME_BODY_NED,
                                 M.MAV_FRAME_BODY_OFFSET_NED, M.MAV_FRAME_BODY_FRD})
GLOBAL_FIELDS = ("lat_int", "lon_int", "alt", "vx", "vy", "vz", "afx", "afy", "afz")


def _target_ok(m, fields: tuple[str, ...]) -> bool:
    """Every field the type_mask says is used is a finite number (ignored fields may hold anything).

    A target with a NaN or infinite value it uses is dropped whole, as if never sent: the
    vehicle keeps its last target (ArduPilot's check_latlng failure; NaN has no meaning here)."""
    used = [getattr(m, name) for bit, name in enumerate(fields) if not m.type_mask & (1 << bit)]
    if not m.type_mask & YAW_IGNORED:
        used.append(m.yaw)
    if not m.type_mask & YAW_RATE_IGNORED:
        used.append(m.yaw_rate)
    return all(math.isfinite(v) for v in used)


def _result(ok: bool) -> int:
    return ACCEPTED if ok else FAILED


class FlightService(Service):
    def __init__(self, ctx, plans) -> None:
        self.ctx = ctx
        self.ap = ctx.autopilot
        plans.guided_handler = self.ap.guided_mission_item  # MISSION_ITEM with current=2

    def message_handlers(self):
        handlers = super().message_handlers()
        if Behaviour.TRACK not in set(self.ctx.vehicle.behaviours.values()):
            handlers.pop("GLOBAL_POSITION_INT", None)  # only an antenna tracker follows other vehicles
        return handlers

    def commands(self):
        table = {
            M.MAV_CMD_NAV_RETURN_TO_LAUNCH: self.rtl, M.MAV_CMD_NAV_LAND: self.land,
            M.MAV_CMD_NAV_LOITER_UNLIM: self.loiter, M.MAV_CMD_MISSION_START: self.mission_start,
            M.MAV_CMD_DO_REPOSITION: self.reposition, M.MAV_CMD_DO_CHANGE_SPEED: self.change_speed,
            M.MAV_CMD_DO_CHANGE_ALTITUDE: self.change_altitude, M.MAV_CMD_DO_SET_HOME: self.set_home,
            M.MAV_CMD_DO_SET_ROI: self.set_roi, M.MAV_CMD_DO_SET_ROI_LOCATION: self.set_roi,
            M.MAV_CMD_DO_SET_ROI_NONE: self.roi_none, M.MAV_CMD_CONDITION_YAW: self.condition_yaw,
            M.MAV_CMD_DO_PAUSE_CONTINUE: self.pause_continue, M.MAV_CMD_DO_SET_SERVO: self.set_servo,
            M.MAV_CMD_DO_REPEAT_SERVO: self.repeat_servo, M.MAV_CMD_DO_SET_RELAY: self.set_relay,
            M.MAV_CMD_DO_REPEAT_RELAY: self.repeat_relay, M.MAV_CMD_DO_FLIGHTTERMINATION: self.terminate,
            M.MAV_CMD_DO_JUMP_TAG: self.jump_tag,
        }
        if "FENCE_ENABLE" in self.ctx.params:
            table[M.MAV_CMD_DO_FENCE_ENABLE] = self.fence_enable
        return table

    # --- modes by command ------------------------------------------------------------------
    def _mode(self, name: str) -> int:
        number = self.ctx.vehicle.mode_number(name)
        if number is None:
            return UNSUPPORTED
        return _result(self.ctx.control.set_mode(number))

    def rtl(self, req: CommandRequest) -> int:
        return self._mode("RTL")

    def land(self, req: CommandRequest) -> int:
        return self._mode("LAND")

    def loiter(self, req: CommandRequest) -> int:
        return self._mode("LOITER")

    def jump_tag(self, req: CommandRequest) -> int:
        """DO_JUMP_TAG: the mission continues from its JUMP_TAG item with this tag (param1)."""
        store = self.ctx.plans.mission
        for seq, item in enumerate(store.stored()):
            if item.command == M.MAV_CMD_JUMP_TAG and item.param1 == req.param1 and seq > 0:
                self.ap.set_current(seq)
                return ACCEPTED
        return FAILED

    def mission_start(self, req: CommandRequest) -> int:
        return _result(self.ap.start_mission(int(req.param1) if math.isfinite(req.param1) else 0))

    # --- guided ----------------------------------------------------------------------------
    def _alt(self, z: float, frame: int) -> float:
        s = self.ctx.state
        return s.home_alt_m + z if frame in RELATIVE_FRAMES else z

    def reposition(self, req: CommandRequest) -> int:
        if not self.ap.in_guided():
            if not int(req.param2) & M.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE:
                return DENIED
            number = self.ctx.vehicle.mode_number("GUIDED")
            if number is None or not self.ctx.control.set_mode(number):
                return FAILED
            self.ap._enter(self.ctx.state.mode)
        s = self.ctx.state
        lat, lon = (req.x / 1e7, req.y / 1e7) if (req.x or req.y) else (s.lat, s.lon)
        alt = self._alt(req.z, req.frame)  # finite: the edge check refuses a NaN altitude (ArduPilot: DENIED)
        speed = req.param1 if req.param1 > 0 else None
        return _result(self.ap.goto(lat, lon, alt, speed))

    def change_speed(self, req: CommandRequest) -> int:
        return _result(self.ap.change_speed(req.param2))

    def change_altitude(self, req: CommandRequest) -> int:
        frame = int(req.param2) if req.param2 else M.MAV_FRAME_GLOBAL_RELATIVE_ALT
        return _result(self.ap.change_altitude(self._alt(req.param1, frame)))

    def set_home(self, req: CommandRequest) -> int:
        """param1 1, or latitude and longitude 0: here (ArduPilot); else the location given."""
        s = self.ctx.state
        if req.param1 >= 1 or not (req.x or req.y):
            return _result(self.ap.set_home(s.lat, s.lon, s.alt_amsl_m))
        return _result(self.ap.set_home(req.x / 1e7, req.y / 1e7, self._alt(req.z, req.frame)))

    def set_roi(self, req: CommandRequest) -> int:
        if not (req.x or req.y):
            return _result(self.ap.set_roi(None))
        return _result(self.ap.set_roi((req.x / 1e7, req.y / 1e7, self._alt(req.z, req.frame))))

    def roi_none(self, req: CommandRequest) -> int:
        return _result(self.ap.set_roi(None))

    def condition_yaw(self, req: CommandRequest) -> int:
        if not self.ap.in_guided() and self.ap.behaviour != Behaviour.AUTO:
            return FAILED
        self.ap.condition_yaw(req.param1, req.param2, req.param3, req.param4)
        return ACCEPTED

    def pause_continue(self, req: CommandRequest) -> int:
        return _result(self.ap.pause(req.param1 == 0))

    # --- outputs ---------------------------------------------------------------------------
    def set_servo(self, req: CommandRequest) -> int:
        return _result(self.ap.outputs.set_servo(int(req.param1), int(req.param2)))

    def repeat_servo(self, req: CommandRequest) -> int:
        return _result(self.ap.outputs.repeat_servo(int(req.param1), int(req.param2), int(req.param3), req.param4))

    def set_relay(self, req: CommandRequest) -> int:
        return _result(self.ap.outputs.set_relay(int(req.param1), req.param2 >= 1))

    def repeat_relay(self, req: CommandRequest) -> int:
        return _result(self.ap.outputs.repeat_relay(int(req.param1), int(req.param2), req.param3))

    def fence_enable(self, req: CommandRequest) -> int:
        if req.param1 not in (0, 1, 2):
            return FAILED
        self.ctx.params.set("FENCE_ENABLE", 1 if req.param1 == 1 else 0, force=True)
        return ACCEPTED

    def terminate(self, req: CommandRequest) -> int:
        if req.param1 > 0.5:
            self.ap.disarm("flight termination")
        return ACCEPTED

    # --- messages --------------------------------------------------------------------------
    def _for_us(self, inc: Incoming) -> bool:
        return inc.msg.target_system == self.ctx.sysid

    def handle_SET_POSITION_TARGET_GLOBAL_INT(self, inc: Incoming) -> None:
        m = inc.msg
        if not self._for_us(inc) or m.coordinate_frame not in GLOBAL_FRAMES or not _target_ok(m, GLOBAL_FIELDS):
            return  # ArduPilot ignores a frame it does not know
        yaw = None if m.type_mask & YAW_IGNORED else math.degrees(m.yaw)
        if m.type_mask & POSITION_IGNORED != POSITION_IGNORED:
            self.ap.goto(m.lat_int / 1e7, m.lon_int / 1e7, self._alt(m.alt, m.coordinate_frame), yaw_deg=yaw)
        elif m.type_mask & VELOCITY_IGNORED != VELOCITY_IGNORED:
            self.ap.velocity(m.vx, m.vy, m.vz, yaw, inc.now)

    def handle_SET_POSITION_TARGET_LOCAL_NED(self, inc: Incoming) -> None:
        m = inc.msg
        if not self._for_us(inc) or m.coordinate_frame not in LOCAL_TARGET_FRAMES or not _target_ok(m, LOCAL_FIELDS):
            return
        s = self.ctx.state
        yaw = None if m.type_mask & YAW_IGNORED else math.degrees(m.yaw)
        body = m.coordinate_frame in (M.MAV_FRAME_BODY_NED, M.MAV_FRAME_BODY_OFFSET_NED, M.MAV_FRAME_BODY_FRD)
        c, sn = math.cos(s.yaw_rad), math.sin(s.yaw_rad)
        rotate = (lambda x, y: (x * c - y * sn, x * sn + y * c)) if body else (lambda x, y: (x, y))
        if m.type_mask & POSITION_IGNORED != POSITION_IGNORED:
            north, east = rotate(m.x, m.y)
            if m.coordinate_frame == M.MAV_FRAME_LOCAL_NED:
                lat, lon = offset(s.home_lat, s.home_lon, north, east)
                alt = s.home_alt_m - m.z
            else:  # offsets from where the vehicle is
                lat, lon = offset(s.lat, s.lon, north, east)
                alt = s.alt_amsl_m - m.z
            self.ap.goto(lat, lon, alt, yaw_deg=yaw)
        elif m.type_mask & VELOCITY_IGNORED != VELOCITY_IGNORED:
            vn, ve = rotate(m.vx, m.vy)
            self.ap.velocity(vn, ve, m.vz, yaw, inc.now)

    def _from_gcs(self, inc: Incoming) -> bool:
        return inc.frame.sysid == self.ctx.gcs_sysid and inc.msg.target_system == self.ctx.sysid

    def handle_RC_CHANNELS_OVERRIDE(self, inc: Incoming) -> None:
        if not self._from_gcs(inc):
            return
        m = inc.msg
        values = {}
        for n in range(1, 19):
            pwm = getattr(m, f"chan{n}_raw", RC_IGNORE)
            if pwm == RC_IGNORE or (n > 8 and pwm in (0, RC_IGNORE)):
                continue
            values[n] = 0 if (n > 8 and pwm == RC_IGNORE - 1) else pwm
        self.ap.rc_override(values, inc.now)

    def handle_MANUAL_CONTROL(self, inc: Incoming) -> None:
        if inc.frame.sysid != self.ctx.gcs_sysid or inc.msg.target != self.ctx.sysid:
            return
        m = inc.msg
        get = self.ctx.params.get

        def pwm(n: int, value: float) -> int:  # value in -1..1 around RCn_TRIM
            trim = get(f"RC{n}_TRIM")
            span = (get(f"RC{n}_MAX") - trim) if value >= 0 else (trim - get(f"RC{n}_MIN"))
            return int(trim + max(-1.0, min(1.0, value)) * span)

        roll, pitch, throttle, yaw = (mapped_channel(self.ctx.params, i) for i in range(4))  # RCMAP_*
        throttle_min, throttle_max = get(f"RC{throttle}_MIN"), get(f"RC{throttle}_MAX")
        values = {roll: pwm(roll, m.y / 1000.0), pitch: pwm(pitch, -m.x / 1000.0),
                  throttle: int(throttle_min + max(0, min(1000, m.z)) / 1000.0 * (throttle_max - throttle_min)),
                  yaw: pwm(yaw, m.r / 1000.0)}
        self.ap.rc_override(values, inc.now)

    def handle_GLOBAL_POSITION_INT(self, inc: Incoming) -> None:
        m = inc.msg
        self.ap.observe_position(inc.frame.sysid, m.lat / 1e7, m.lon / 1e7, m.alt / 1000.0)
