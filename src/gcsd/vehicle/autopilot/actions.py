"""What commands and mission items ask the autopilot to do (a part of `Autopilot`).

Guided targets (DO_REPOSITION, SET_POSITION_TARGET_*, MISSION_ITEM current=2/3), takeoff and
landing, mission start, speed, region of interest and yaw, servos and relays, home, pause and
continue, RC overrides and MANUAL_CONTROL (held RC_OVERRIDE_TIME seconds of real time), the
position of the vehicle an antenna tracker follows. Each returns whether it was done; the
command layer turns that into a MAV_RESULT. Mission DO items dispatch through `DO_TABLE`.

The message layer refuses NaN, infinity and out-of-range values before they get here; these
entry points check again (`location_ok`, `finite`) and refuse, because an embedding program
calls them directly and a bad value in the state would break every telemetry message after it.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.autopilot.settings import Behaviour as B
from gcsd.vehicle.mission.items import LOCATION_ALT_MAX_M, MissionItem, check_values
from gcsd.vehicle.sim.geo import distance_m, wrap_180
from gcsd.vehicle.sim.state import Kind, Setpoint

RC_MIN, RC_MAX = 800, 2200


def finite(*values: float) -> bool:
    return all(math.isfinite(v) for v in values)


def location_ok(lat: float, lon: float, alt: float) -> bool:
    """A position the state can hold: a real latitude/longitude, an altitude within +-83 km."""
    return finite(lat, lon, alt) and -90 <= lat <= 90 and -180 <= lon <= 180 and abs(alt) <= LOCATION_ALT_MAX_M


class Actions:
    # --- takeoff and landing -------------------------------------------------------------------
    def takeoff_alt_m(self) -> float:
        override = getattr(self, "_takeoff_alt_override", None)
        return override if override is not None else self.settings.takeoff_alt_m

    def set_takeoff_alt(self, alt_m: float | None) -> None:
        self._takeoff_alt_override = alt_m if alt_m and alt_m > 0 else None

    def takeoff(self, alt_rel_m: float) -> bool:
        """Guided takeoff to alt_rel_m above home: armed, in a guided behaviour, on the ground."""
        self.sync()
        s = self.state
        if not s.armed or self.behaviour != B.GUIDED or not s.on_ground or not 0 < alt_rel_m <= LOCATION_ALT_MAX_M:
            return False
        self.guided = Setpoint(Kind.TAKEOFF, s.lat, s.lon, s.home_alt_m + alt_rel_m)
        return True

    def takeoff_setpoint(self, alt: float) -> Setpoint:
        s = self.state
        if self.settings.ignore_alt_for_waypoints:
            return Setpoint(Kind.HOLD, s.lat, s.lon, s.alt_amsl_m)
        return Setpoint(Kind.TAKEOFF, s.lat, s.lon, alt)

    def takeoff_done(self, alt: float) -> bool:
        s = self.state
        if self.settings.ignore_alt_for_waypoints:
            return True
        if self.settings.fixed_wing:
            return s.alt_amsl_m >= alt - max(TAKEOFF_TOLERANCE_M, 0.1 * (alt - s.home_alt_m))
        return s.alt_amsl_m >= alt - TAKEOFF_TOLERANCE_M

    def land_setpoint(self, lat: float, lon: float) -> Setpoint:
        if self.settings.ignore_alt_for_waypoints:
            return Setpoint(Kind.GOTO, lat, lon, self.state.alt_amsl_m)
        return Setpoint(Kind.LAND, lat, lon, self.state.ground_m)

    def landed_after_landing(self) -> bool:
        s = self.state
        return s.on_ground and s.groundspeed_ms < 0.5

    # --- guided --------------------------------------------------------------------------------
    def in_guided(self) -> bool:
        self.sync()
        return self.behaviour == B.GUIDED

    def goto(self, lat: float, lon: float, alt_amsl: float, speed: float | None = None,
             yaw_deg: float | None = None) -> bool:
        if not location_ok(lat, lon, alt_amsl) or not finite(speed or 0.0, yaw_deg or 0.0):
            return False
        if not self.in_guided() or not self.state.armed:
            return False
        self.guided = Setpoint(Kind.GOTO, lat, lon, alt_amsl, speed, yaw_deg)
        self.guided_expires_s = None
        return True

    def velocity(self, vn: float, ve: float, vd: float, yaw_deg: float | None, now: float) -> bool:
        if not finite(vn, ve, vd, yaw_deg or 0.0):
            return False
        if not self.in_guided() or not self.state.armed:
            return False
        self.guided = Setpoint(Kind.VELOCITY, velocity=(vn, ve, vd), yaw_deg=yaw_deg)
        self.guided_expires_s = now + self.settings.guided_timeout_s
        return True

    def change_altitude(self, alt_amsl: float) -> bool:
        if not finite(alt_amsl) or abs(alt_amsl) > LOCATION_ALT_MAX_M:
            return False
        if not self.in_guided() or not self.state.armed:
            return False
        g = self.guided if self.guided is not None and self.guided.kind in (Kind.GOTO, Kind.HOLD) else self._here(Kind.HOLD)
        self.guided = Setpoint(g.kind, g.lat, g.lon, alt_amsl, g.speed_ms, g.yaw_deg)
        return True

    def guided_mission_item(self, item: MissionItem, current: int) -> bool:
        """MISSION_ITEM(_INT) with current 2 (fly to) or 3 (change altitude), in GUIDED."""
        from gcsd.vehicle.autopilot.mission import item_location
        if check_values(item) != M.MAV_MISSION_ACCEPTED:
            return False
        lat, lon, alt = item_location(item, self.state)
        if current == 3:
            return self.change_altitude(alt)
        return self.goto(lat, lon, alt)

    # --- missions -------------------------------------------------------------------------------
    def start_mission(self, first: int) -> bool:
        self.sync()
        store = self.ctx.plans.mission
        if store.count() <= 1 or not self.state.armed:
            return False
        if first > 0 and not store.set_current(first):
            return False
        self.runner.start(first if first > 0 else None, restart=True)
        if not self.set_mode("AUTO"):
            return False
        self._enter(self.state.mode)
        if first > 0:
            self.runner.start(first, restart=True)
        return True

    def change_speed(self, speed_ms: float) -> bool:
        if speed_ms is None or not math.isfinite(speed_ms) or speed_ms < -2.0:
            return False
        if speed_ms > 0:
            self.speed_override = min(speed_ms, max(self.limits.max_speed_ms, self.limits.max_airspeed_ms))
        elif speed_ms == -2.0 or speed_ms == 0.0:
            self.speed_override = None
        return True

    def pause(self, pause: bool) -> bool:
        self.sync()
        if self.behaviour not in (B.AUTO, B.GUIDED):
            return False
        self.paused = self._here(Kind.HOLD) if pause and not self.state.on_ground else None
        return True

    def motor_test(self, motor: int, throttle_pct: float, seconds: float) -> None:
        get = self.params.get
        lo, hi = get(f"SERVO{motor}_MIN"), get(f"SERVO{motor}_MAX")
        self.outputs.motor_test(motor, int(lo + (hi - lo) * throttle_pct / 100.0), seconds)

    # --- pointing -------------------------------------------------------------------------------
    def set_roi(self, location: tuple[float, float, float] | None) -> bool:
        if location is not None and not location_ok(*location):
            return False
        if self.mount_roi is not None and self.mount_roi(location):
            self.roi = None  # a gimbal that pans points the camera; the vehicle keeps its heading
            return True
        self.roi = location
        if location is not None:
            self.yaw_target = None
        return True

    def condition_yaw(self, angle: float, rate: float, direction: float, relative: float) -> None:
        if not finite(angle, direction, relative):
            return
        heading = self.state.heading_deg
        if relative:
            target = heading + (angle if direction >= 0 else -angle)
        else:
            target = angle
        self.yaw_target = target % 360.0

    def observe_position(self, sysid: int, lat: float, lon: float, alt: float) -> None:
        """GLOBAL_POSITION_INT from another system: what an antenna tracker follows."""
        wanted = self.settings.track_sysid
        if not location_ok(lat, lon, alt):
            return
        if sysid != self.ctx.sysid and (wanted == 0 or wanted == sysid):
            self.tracked = (lat, lon, alt)

    # --- home ------------------------------------------------------------------------------------
    def set_home(self, lat: float, lon: float, alt: float, locked: bool = True) -> bool:
        if not location_ok(lat, lon, alt):
            return False
        s = self.state
        s.home_lat, s.home_lon, s.home_alt_m = lat, lon, alt
        s.has_home = True
        self.home_locked = self.home_locked or locked
        self.ctx.plans.home_changed()
        self.ctx.push(M.MAVLINK_MSG_ID_HOME_POSITION)
        self.ctx.push(M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
        return True

    # --- sticks ----------------------------------------------------------------------------------
    def rc_override(self, values: dict[int, int], now: float) -> None:
        s = self.state
        for n, pwm in values.items():
            if pwm == 0:
                s.rc_override.pop(n, None)
            elif RC_MIN <= pwm <= RC_MAX:
                s.rc_override[n] = pwm
                self.rc.used = True  # from now on their lapse is RC loss (gcsd.vehicle.types.rc)
        self._rc_override_s = now

    def rc_tick(self, now: float) -> None:
        """Each tick: overrides lapse after RC_OVERRIDE_TIME; the flight-mode switch is read."""
        s = self.state
        hold_s = float(self.params.get("RC_OVERRIDE_TIME")) if "RC_OVERRIDE_TIME" in self.params else 3.0
        since = getattr(self, "_rc_override_s", None)
        if s.rc_override and since is not None and hold_s >= 0 and now - since > hold_s:
            s.rc_override.clear()
        mode = self.rc.mode_switch(self.params, s.rc_override, now)
        control = self.ctx.control
        if mode is not None:
            control.set_mode(mode)  # refused with a STATUSTEXT, as a ground station's request
        gesture = self.rc.rudder_arming(self.params, s.rc_override, now, s.armed)
        if gesture == "arm":
            control.arm_by_rudder()
        elif gesture == "disarm" and s.on_ground:
            control.disarm_by_rudder()

    def sticks(self, now: float) -> tuple[float, float, float, float]:
        """Roll, pitch, throttle, yaw in -1..1 from RC overrides: RCMAP_*, RCn_TRIM/_DZ/_MIN/_MAX/
        _REVERSED as ArduPilot reads them (gcsd.vehicle.types.rc)."""
        return self.rc.sticks(self.params, self.state.rc_override)

    # --- the mission runner's view -----------------------------------------------------------
    def mission_items(self):
        return self.ctx.plans.mission.stored()

    def current_seq(self) -> int:
        return self.ctx.plans.mission.current_seq

    def set_current(self, seq: int) -> None:
        store = self.ctx.plans.mission
        if store.current_seq != seq and store.set_current(seq):
            self.ctx.push(M.MAVLINK_MSG_ID_MISSION_CURRENT)

    def reached(self, seq: int) -> None:
        self.ctx.plans.item_reached(seq)

    def rally_items(self):
        return self.ctx.plans.rally.stored()

    def _fence_items(self):
        return self.ctx.plans.fence.stored()

    def accept_radius_m(self) -> float:
        return self.settings.accept_radius_m or self.limits.wp_radius_m

    def loiter_radius_m(self) -> float:
        return self.limits.loiter_radius_m if self.settings.fixed_wing else max(self.limits.wp_radius_m, 1.0)

    def at(self, lat: float, lon: float, alt: float, radius: float, check_alt: bool = True) -> bool:
        s = self.state
        if distance_m(s.lat, s.lon, lat, lon) > radius:
            return False
        if not check_alt or self.settings.ignore_alt_for_waypoints or self.settings.fixed_wing:
            return True
        return abs(s.alt_amsl_m - alt) <= max(TAKEOFF_TOLERANCE_M, radius)

    def yaw_reached(self) -> bool:
        if self.yaw_target is None or self.settings.fixed_wing:
            return True
        return abs(wrap_180(self.yaw_target - self.state.heading_deg)) < 2.0

    # --- mission DO items --------------------------------------------------------------------------
    def do_command(self, item: MissionItem) -> None:
        payload = self.payload_items.get(item.command)  # the camera's mission items, when it has one
        if payload is not None:
            payload(item)
            return
        handler = DO_TABLE.get(item.command)
        if handler is not None:
            handler(self, item)


def _do_change_speed(ap, item):
    ap.change_speed(item.param2)


def _do_set_servo(ap, item):
    ap.outputs.set_servo(int(item.param1), int(item.param2))


def _do_repeat_servo(ap, item):
    ap.outputs.repeat_servo(int(item.param1), int(item.param2), int(item.param3), item.param4)


def _do_set_relay(ap, item):
    ap.outputs.set_relay(int(item.param1), item.param2 >= 1)


def _do_repeat_relay(ap, item):
    ap.outputs.repeat_relay(int(item.param1), int(item.param2), item.param3)


def _do_set_home(ap, item):
    s = ap.state
    if item.param1 >= 1 or not (item.x or item.y):
        ap.set_home(s.lat, s.lon, s.alt_amsl_m)
    else:
        from gcsd.vehicle.autopilot.mission import item_location
        ap.set_home(*item_location(item, s))


def _do_set_roi(ap, item):
    from gcsd.vehicle.autopilot.mission import item_location
    ap.set_roi(None if not (item.x or item.y) else item_location(item, ap.state))


def _do_roi_none(ap, item):
    ap.set_roi(None)


def _do_fence_enable(ap, item):
    if "FENCE_ENABLE" in ap.params:
        ap.params.set("FENCE_ENABLE", 1 if item.param1 >= 1 else 0, force=True)


DO_TABLE = {
    M.MAV_CMD_DO_CHANGE_SPEED: _do_change_speed,
    M.MAV_CMD_DO_SET_SERVO: _do_set_servo,
    M.MAV_CMD_DO_REPEAT_SERVO: _do_repeat_servo,
    M.MAV_CMD_DO_SET_RELAY: _do_set_relay,
    M.MAV_CMD_DO_REPEAT_RELAY: _do_repeat_relay,
    M.MAV_CMD_DO_SET_HOME: _do_set_home,
    M.MAV_CMD_DO_SET_ROI: _do_set_roi,
    M.MAV_CMD_DO_SET_ROI_LOCATION: _do_set_roi,
    M.MAV_CMD_DO_SET_ROI_NONE: _do_roi_none,
    M.MAV_CMD_DO_FENCE_ENABLE: _do_fence_enable,
}

TAKEOFF_TOLERANCE_M = 1.0
