"""The autopilot of a vehicle node: modes, guided targets, missions, RTL, landing, failsafes.

Theory of operation. `step(now)` runs from the daemon's simulation task (gcs.py `_simulate`,
independent of the links); at most SIM_RATE_HZ times a
real second it advances simulated time by the real time elapsed x SIM_SPEEDUP, cut into ticks
of at most MAX_STEP_S. Each tick: notice mode and arming changes made by services (entering a
mode sets up its behaviour: RTL picks its destination, AUTO resumes the mission, LAND fixes
its point...), run the failsafes, compute the `Setpoint` of the current behaviour (a table:
behaviour -> method), hand it to the backend (the simulation, or an embedding program's
backend), then act on what happened: a touchdown in an autonomous landing disarms, a copter
left idle on the ground disarms after DISARM_DELAY, a finished takeoff holds, the end of a
mission switches to the vehicle's mission-end mode. Mission items and their DO commands run in
`MissionRunner`; RTL in `Rtl`; servos and relays in `Outputs`; failsafes in `Failsafes`.

What it tells the world goes through the node: STATUSTEXT (`send_text`), an immediate
HEARTBEAT on every mode or arming change, MISSION_CURRENT / MISSION_ITEM_REACHED through the
mission service, HOME_POSITION when home moves. It never asks which vehicle type it drives:
behaviours, limits and failsafe actions come from the vehicle type's data.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.autopilot.actions import Actions
from gcsd.vehicle.autopilot.failsafe import Failsafes
from gcsd.vehicle.autopilot.mission import MissionRunner
from gcsd.vehicle.autopilot.outputs import Outputs
from gcsd.vehicle.autopilot.rtl import Rtl
from gcsd.vehicle.autopilot.settings import DISARM
from gcsd.vehicle.autopilot.settings import Behaviour as B
from gcsd.vehicle.mission.items import MissionItem
from gcsd.vehicle.sim import MAX_STEP_S, SimulatedVehicle
from gcsd.vehicle.sim.geo import bearing_deg, distance_m, ne_m
from gcsd.vehicle.sim.state import Kind, Setpoint
from gcsd.vehicle.types.common import environment
from gcsd.vehicle.types.rc import RcInput

log = structlog.get_logger("gcsd.vehicle.autopilot")

MAX_CATCH_UP_S = 30.0  # simulated seconds per step at most (after a stall)
DEFAULT_SIM_PERIOD_S = 0.04  # SIM_RATE_HZ 25, for a vehicle type without the parameter
TAKEOFF_TOLERANCE_M = 1.0


class Autopilot(Actions):
    def __init__(self, ctx, backend=None, now: float = 0.0, speedup: float = 1.0) -> None:
        self.ctx = ctx
        self.state = ctx.state
        self.vehicle = ctx.vehicle
        self.params = ctx.params
        self.simulated = backend is None
        if backend is None and ctx.vehicle.dynamics is not None:
            backend = SimulatedVehicle(ctx.vehicle.dynamics(), environment(ctx.params.clamped))
        self.backend = backend
        self.speedup = float(self.params.clamped("SIM_SPEEDUP")) if "SIM_SPEEDUP" in self.params else speedup
        self.period_s = 1.0 / float(self.params.clamped("SIM_RATE_HZ")) if "SIM_RATE_HZ" in self.params else DEFAULT_SIM_PERIOD_S
        self._last_s = now
        self._dirty = True
        self._reload()
        for d in self.vehicle.params + tuple(self._sim_param_names()):
            self.params.on_change(d if isinstance(d, str) else d.name, self._param_changed)
        self.runner = MissionRunner(self)
        self.rtl = Rtl(self)
        self.outputs = Outputs(self.state, self.params)
        self.failsafes = Failsafes()
        self.rc = RcInput()
        self._mode = None
        self._armed = self.state.armed
        self.behaviour = B.IDLE
        self.guided: Setpoint | None = None
        self.guided_expires_s: float | None = None
        self.hold: Setpoint = Setpoint(Kind.IDLE)
        self.speed_override: float | None = None
        self.roi: tuple[float, float, float] | None = None
        # payload hooks (gcsd.payloads.gimbal, gcsd.payloads.camera): an ROI the gimbal takes, mission items the camera runs
        self.mount_roi: Callable[[tuple[float, float, float] | None], bool] | None = None
        self.payload_items: dict[int, Callable[[MissionItem], None]] = {}
        self.yaw_target: float | None = None
        self.paused: Setpoint | None = None
        self.home_locked = False
        self.tracked: tuple[float, float, float] | None = None
        self.reversed = False
        self._touchdown_s: float | None = None
        self._idle_since: float | None = None
        self._mission_ended = False
        self._sim_ms = 0
        self._setpoints = {
            B.IDLE: self._sp_idle, B.MANUAL: self._sp_manual, B.HOLD: self._sp_hold, B.GUIDED: self._sp_guided,
            B.AUTO: self._sp_auto, B.RTL: self._sp_rtl, B.LAND: self._sp_land, B.TAKEOFF: self._sp_takeoff,
            B.CIRCLE: self._sp_circle, B.SURFACE: self._sp_hold, B.SCAN: self._sp_scan, B.TRACK: self._sp_track,
        }

    # --- parameters --------------------------------------------------------------------------
    def _sim_param_names(self):
        return [n for n in ("SIM_SPEEDUP", "SIM_RATE_HZ", "SIM_WIND_SPD", "SIM_WIND_DIR", "SIM_WIND_TURB",
                            "SIM_GPS_DISABLE", "SIM_GPS_NUMSATS", "SIM_GPS_HDOP") if n in self.params]

    def _param_changed(self, _name, _value) -> None:
        self._dirty = True

    def _reload(self) -> None:
        get = self.params.clamped  # a value outside its documented range acts as the nearest bound
        self.settings = self.vehicle.settings(get)
        self.limits = self.settings.limits
        if "SIM_SPEEDUP" in self.params:
            self.speedup = float(get("SIM_SPEEDUP"))
            self.period_s = 1.0 / float(get("SIM_RATE_HZ"))
        if self.simulated and self.backend is not None:
            self.backend.environment = environment(get)
        self._dirty = False

    @property
    def speed_ms(self) -> float:
        return self.speed_override if self.speed_override is not None else self.limits.cruise_speed_ms

    # --- time --------------------------------------------------------------------------------
    def step(self, now: float) -> None:
        elapsed = now - self._last_s
        if elapsed < self.period_s:
            return
        self._last_s = now
        if self.backend is None:
            return
        total = min(elapsed * self.speedup, MAX_CATCH_UP_S)
        ticks = max(1, math.ceil(total / MAX_STEP_S - 1e-9))
        dt = total / ticks
        for _ in range(ticks):
            self._tick(dt, now)

    def _tick(self, dt: float, now: float) -> None:
        s = self.state
        s.time_s += dt
        self._sim_ms = int(s.time_s * 1000)
        if self._dirty:
            self._reload()
        self.sync()
        self.rc_tick(now)
        last_seen = self.ctx.control.gcs_last_seen_s
        for event in self.failsafes.check(s, self.settings, self.params, last_seen, now, self._fence_items(),
                                          self._sim_ms, rc_lost=self.rc.lost(self.params, s.rc_override)):
            self.ctx.text(event.severity, event.text)
            if event.action is not None:
                self.act(event.action, f"{event.text}")
        sp = self.paused or self._setpoints[self.behaviour](s, dt, now)
        if self.behaviour in (B.GUIDED, B.AUTO) and not self.settings.fixed_wing:
            if self.yaw_target is not None:
                sp.yaw_deg = self.yaw_target
            elif self.roi is not None:
                sp.yaw_deg = bearing_deg(s.lat, s.lon, self.roi[0], self.roi[1])
        if sp.yaw_deg is None and self.behaviour in self.settings.keep_yaw_in:  # WP_YAW_BEHAVIOR
            sp = dataclasses.replace(sp, yaw_deg=s.heading_deg)
        sp.reverse = self.reversed
        self.outputs.tick(dt)
        self.backend.update(s, sp, self.limits, dt)
        self._after(sp, dt, now)
        self._nav_info(sp)

    def sync(self) -> None:
        """Catch up with mode and arming changes made by services since the last tick."""
        s = self.state
        if s.mode != self._mode:
            self._enter(s.mode)
        if s.armed != self._armed:
            self._armed = s.armed
            self._on_arming(s.armed)

    # --- modes -------------------------------------------------------------------------------
    def refuse_mode(self, number: int) -> str | None:
        """Why the vehicle cannot enter mode `number` now (None: it can)."""
        behaviour = self.vehicle.behaviour(number)
        needs_position = behaviour in (B.GUIDED, B.AUTO, B.RTL, B.CIRCLE, B.TRACK)
        if needs_position and self.state.gps_fix_type < 3:
            return "requires position"
        if behaviour == B.AUTO and self.ctx.plans.mission.count() <= 1:
            return "no mission"
        return None

    def set_mode(self, name: str) -> bool:
        number = self.vehicle.mode_number(name)
        if number is None:
            return False
        if self.state.mode != number:
            self.state.mode = number
            self.ctx.push(M.MAVLINK_MSG_ID_HEARTBEAT)
        return True

    def act(self, action: str, reason: str) -> None:
        """A failsafe's or a mission end's action: DISARM, or a mode by name."""
        if action == DISARM:
            self.disarm(reason)
        elif not self.set_mode(action):
            log.warning("failsafe_mode_unknown", mode=action, vehicle=self.vehicle.name)

    def _enter(self, mode: int) -> None:
        s = self.state
        self._mode = mode
        self.behaviour = self.vehicle.behaviour(mode)
        self.guided = None
        self.paused = None
        self.yaw_target = None
        self._touchdown_s = None
        self.hold = self._here(Kind.HOLD if not s.on_ground else Kind.IDLE)
        if self.behaviour == B.AUTO:
            restart = self.runner.complete or self.ctx.plans.complete
            if restart:
                self.ctx.plans.mission.set_current(1)
            self.runner.start(restart=restart)
            self._mission_ended = False
        elif self.behaviour == B.RTL:
            self.rtl.begin(s)
        elif self.behaviour == B.LAND:
            self.hold = Setpoint(Kind.LAND, s.lat, s.lon, s.ground_m)
        elif self.behaviour == B.CIRCLE:
            self.hold = self._here(Kind.HOLD)
        elif self.behaviour == B.SURFACE:
            self.hold = Setpoint(Kind.LAND, s.lat, s.lon, s.ground_m)
        elif self.behaviour == B.TAKEOFF:
            self.hold = Setpoint(Kind.TAKEOFF, s.lat, s.lon, s.home_alt_m + self.takeoff_alt_m())

    def _here(self, kind: Kind) -> Setpoint:
        s = self.state
        return Setpoint(kind, s.lat, s.lon, s.alt_amsl_m)

    # --- setpoints per behaviour ------------------------------------------------------------
    def _sp_idle(self, s, dt, now) -> Setpoint:
        return Setpoint(Kind.IDLE)

    def _sp_manual(self, s, dt, now) -> Setpoint:
        return Setpoint(Kind.MANUAL, sticks=self.sticks(now))

    def _sp_hold(self, s, dt, now) -> Setpoint:
        if self.hold.kind == Kind.IDLE and s.armed and not s.on_ground:
            self.hold = self._here(Kind.HOLD)
        return self.hold

    def _sp_guided(self, s, dt, now) -> Setpoint:
        g = self.guided
        if g is None:
            return self._sp_hold(s, dt, now)
        if g.kind == Kind.VELOCITY and self.guided_expires_s is not None and now > self.guided_expires_s:
            self.guided = None
            self.hold = self._here(Kind.HOLD)
            return self.hold
        if g.kind == Kind.TAKEOFF and self.takeoff_done(g.alt_m):
            self.guided = Setpoint(Kind.HOLD, g.lat, g.lon, g.alt_m)
            return self.guided
        return g

    def _sp_auto(self, s, dt, now) -> Setpoint:
        if self._mission_ended:
            return self.hold
        sp = self.runner.tick(s, dt)
        if sp is not None:
            return sp
        self._mission_ended = True
        self.hold = self._here(Kind.HOLD if not s.on_ground else Kind.IDLE)
        if self.settings.mission_end is not None and not s.on_ground:
            self.set_mode(self.settings.mission_end)
        return self.hold

    def _sp_rtl(self, s, dt, now) -> Setpoint:
        return self.rtl.tick(s, dt)

    def _sp_land(self, s, dt, now) -> Setpoint:
        return self.hold

    def _sp_takeoff(self, s, dt, now) -> Setpoint:
        if self.hold.kind == Kind.TAKEOFF and self.takeoff_done(self.hold.alt_m):
            self.hold = Setpoint(Kind.HOLD, s.lat, s.lon, self.hold.alt_m)  # loiter at the takeoff altitude
        return self.hold

    def _sp_circle(self, s, dt, now) -> Setpoint:
        center = self.hold
        radius = max(self.settings.circle_radius_m, 1.0)
        if self.settings.fixed_wing:
            return Setpoint(Kind.HOLD, center.lat, center.lon, center.alt_m, radius_m=radius)
        bearing = bearing_deg(center.lat, center.lon, s.lat, s.lon) if distance_m(
            center.lat, center.lon, s.lat, s.lon) > 0.5 else math.degrees(s.yaw_rad)
        lead = math.copysign(25.0, self.settings.circle_rate_dps or 1.0)
        from gcsd.vehicle.sim.geo import offset
        ahead = math.radians(bearing + lead)
        lat, lon = offset(center.lat, center.lon, radius * math.cos(ahead), radius * math.sin(ahead))
        speed = min(self.limits.max_speed_ms, abs(math.radians(self.settings.circle_rate_dps)) * radius) or 1.0
        return Setpoint(Kind.GOTO, lat, lon, center.alt_m, speed)

    def _sp_scan(self, s, dt, now) -> Setpoint:
        return Setpoint(Kind.SCAN, speed_ms=self.settings.extra.get("scan_rate_dps"))  # deg/s for a tracker

    def _sp_track(self, s, dt, now) -> Setpoint:
        if self.tracked is None:
            return Setpoint(Kind.IDLE)
        lat, lon, alt = self.tracked
        return Setpoint(Kind.POINT, lat, lon, alt)

    # --- after the backend moved -------------------------------------------------------------
    def _after(self, sp: Setpoint, dt: float, now: float) -> None:
        s = self.state
        if not s.armed:
            self._touchdown_s = None
            self._idle_since = None
            return
        if sp.kind == Kind.LAND and self.landed_after_landing():
            if self._touchdown_s is None:
                self._touchdown_s = s.time_s
                self.ctx.text(M.MAV_SEVERITY_INFO, "Landed")
            if s.time_s - self._touchdown_s >= self.settings.land_disarm_delay_s:
                if self.behaviour == B.AUTO:
                    self.runner.tick(s, 0.0)  # the mission's LAND item completes before the disarm
                self.disarm("landed")
            return
        delay = self.settings.extra.get("disarm_delay_s", 0.0)
        idle = s.on_ground and sp.kind in (Kind.IDLE, Kind.HOLD, Kind.MANUAL) and (
            sp.kind != Kind.MANUAL or sp.sticks[2] <= 0.0)
        if delay > 0 and idle:
            if self._idle_since is None:
                self._idle_since = now
            elif now - self._idle_since >= delay:
                self.disarm("auto disarm")
        else:
            self._idle_since = None

    def _nav_info(self, sp: Setpoint) -> None:
        s = self.state
        if sp.kind in (Kind.GOTO, Kind.HOLD, Kind.LAND, Kind.TAKEOFF, Kind.POINT) and (sp.lat or sp.lon):
            s.target = (sp.lat, sp.lon, sp.alt_m)
            north, east = ne_m(s.lat, s.lon, sp.lat, sp.lon)
            s.wp_dist_m = math.hypot(north, east)
            s.target_bearing_deg = math.degrees(math.atan2(east, north)) % 360.0
            s.alt_error_m = sp.alt_m - s.alt_amsl_m
        else:
            s.target = None
            s.wp_dist_m = 0.0
            s.alt_error_m = 0.0
            s.target_bearing_deg = s.heading_deg

    # --- arming ------------------------------------------------------------------------------
    def _on_arming(self, armed: bool) -> None:
        s = self.state
        if armed:
            if not self.home_locked:
                self.set_home(s.lat, s.lon, s.alt_amsl_m, locked=False)
            self._touchdown_s = None
            self._idle_since = None
            if self.behaviour == B.TAKEOFF or self.behaviour == B.AUTO:
                self._enter(s.mode)
        else:
            self.guided = None
            self.roi = None
            self.paused = None

    def disarm(self, reason: str) -> None:
        s = self.state
        if not s.armed:
            return
        s.armed = False
        self._armed = False
        self._on_arming(False)
        self.ctx.text(M.MAV_SEVERITY_INFO, "Disarming motors")
        self.ctx.push(M.MAVLINK_MSG_ID_HEARTBEAT)
        log.info("vehicle_disarmed", sysid=self.ctx.sysid, reason=reason)

    def reboot(self) -> None:
        """A simulated reboot: disarmed, initial mode, mission from the start, everything reset."""
        s = self.state
        s.armed = self._armed = False
        s.mode = self.vehicle.initial_mode
        s.failsafe = None
        s.rc_override.clear()
        s.servo_override.clear()
        s.relays[:] = [False] * len(s.relays)
        self.failsafes = Failsafes()
        self.rc = RcInput()
        self.outputs = Outputs(s, self.params)
        self.runner = MissionRunner(self)
        self.ctx.plans.mission.set_current(0)
        self.speed_override = self.roi = self.yaw_target = self.paused = None
        self.home_locked = False
        self.reversed = False
        self._enter(s.mode)
        self.ctx.push(M.MAVLINK_MSG_ID_HEARTBEAT)

    def backend_prearm_failures(self) -> list[str]:
        check = getattr(self.backend, "prearm_failures", None)
        return list(check()) if check is not None else []
