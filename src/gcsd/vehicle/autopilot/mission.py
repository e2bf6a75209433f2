"""Flying the mission: the nav item in progress, the DO and CONDITION items queued behind it.

As ArduPilot's AP_Mission: the mission advances from the current item to the next NAV
command, following DO_JUMP (param1 target, param2 repeats, -1 forever; counters reset when
the mission restarts) and queueing the DO_/CONDITION_ items met on the way. The NAV item runs
(its setpoint each tick, its own completion test); meanwhile the queue runs in order: a
CONDITION (DELAY seconds, DISTANCE metres to the nav target, YAW reached) holds the DO items
behind it; a DO item runs at once (`pilot.do_command`). When the NAV item completes, what is
left of the queue is dropped, MISSION_ITEM_REACHED is sent (`pilot.reached(seq)`) and the next
NAV item becomes current (`pilot.set_current(seq)`, which MISSION_CURRENT reports). A change of
the store's current item from outside (MISSION_SET_CURRENT) restarts from that item.

Work per step is bounded, as ArduPilot verifies one NAV command per update: a tick completes at
most one NAV item and searches once for the next, which starts on the following tick (no
recursion, however many items complete at once). The search follows at most MAX_JUMPS_PER_SEARCH
DO_JUMPs (AP_Mission's 64), and a repeat-forever jump reached twice in one search (a loop with no
NAV item in it, which can never end) stops it; either ends the mission as ArduPilot's does.

NAV items: WAYPOINT and SPLINE_WAYPOINT (hold param1 s, acceptance radius param2), TAKEOFF,
LAND, RETURN_TO_LAUNCH, LOITER_UNLIM, LOITER_TIME (param1 s) and LOITER_TURNS (param1 turns,
at most 255), both with param3 the radius (at most 2550 m, as ArduPilot stores it; negative
counter-clockwise), LOITER_TO_ALT, DELAY (param1 s); any other NAV command completes at once.
Items hold no NaN or infinity where one would be used (the stores refuse them, items.check_values). Latitude and longitude 0 mean "here". Altitudes follow the frame:
GLOBAL is above mean sea level, the relative and terrain frames above home.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission.items import MissionItem
from gcsd.vehicle.sim.geo import bearing_deg, distance_m, offset, wrap_180
from gcsd.vehicle.sim.state import Kind, Setpoint

NAV_LAST = M.MAV_CMD_NAV_LAST
ABSOLUTE_FRAMES = frozenset({M.MAV_FRAME_GLOBAL, M.MAV_FRAME_GLOBAL_INT})
ALT_TOLERANCE_M = 1.0
ORBIT_LEAD_DEG = 25.0
MAX_LOITER_RADIUS_M = 2550.0  # the largest radius ArduPilot's mission storage keeps (255 x 10 m)
MAX_TURNS = 255  # LOITER_TURNS is stored in 8 bits
MAX_JUMPS_PER_SEARCH = 64  # AP_Mission::get_next_cmd's max_loops


def is_nav(command: int) -> bool:
    return command <= NAV_LAST


def item_location(item: MissionItem, s) -> tuple[float, float, float]:
    """(lat, lon, alt AMSL) of an item; 0/0 is the current position, z by frame."""
    lat, lon = (item.x / 1e7, item.y / 1e7) if (item.x or item.y) else (s.lat, s.lon)
    alt = item.z if item.frame in ABSOLUTE_FRAMES else s.home_alt_m + item.z
    return lat, lon, alt


class MissionRunner:
    def __init__(self, pilot) -> None:
        self.pilot = pilot
        self.nav_seq: int | None = None
        self.cursor = 1
        self.queue: list[tuple[int, MissionItem]] = []
        self.complete = False
        self._jumps: dict[int, int] = {}
        self._nav: dict = {}
        self._cond: dict = {}
        self._synced_seq: int | None = None

    # --- control -----------------------------------------------------------------------------
    def start(self, seq: int | None = None, restart: bool = False) -> None:
        if restart:
            self._jumps.clear()
        self.cursor = max(1, seq if seq is not None else self.pilot.current_seq())
        self.nav_seq = None
        self.queue.clear()
        self.complete = False
        self._synced_seq = None

    def items(self) -> tuple[MissionItem, ...]:
        return self.pilot.mission_items()

    # --- the tick ------------------------------------------------------------------------------
    def tick(self, s, dt: float) -> Setpoint | None:
        """The setpoint of the nav item in progress; None once the mission is complete."""
        current = self.pilot.current_seq()
        if self._synced_seq is not None and current != self._synced_seq:
            self.start(current)  # MISSION_SET_CURRENT from a ground station
        if self.complete:
            return None
        items = self.items()
        if self.nav_seq is None and not self._advance(items, s):
            return None
        item = items[self.nav_seq] if self.nav_seq < len(items) else None
        if item is None:
            self.complete = True
            return None
        self._run_queue(s, dt)
        sp, done = self._nav_step(item, s, dt)
        if done:
            seq = self.nav_seq
            self.queue.clear()
            self.nav_seq = None
            self.cursor = seq + 1
            self.pilot.reached(seq)
            if not self._advance(items, s):
                return None
            if sp is None:  # a NAV command with nothing to fly: stay put until the next starts
                sp = Setpoint(Kind.IDLE if s.on_ground else Kind.HOLD, s.lat, s.lon, s.alt_amsl_m)
        return sp

    def _advance(self, items, s) -> bool:
        """Find the next NAV item from the cursor, queueing DO/CONDITION items; False at the end
        (also when the search meets AP_Mission's jump limits)."""
        seq = self.cursor
        jumps_followed = 0
        jumps_seen: set[int] = set()
        before: dict[int, MissionItem] = {}  # DO items met before the NAV item run with it, once each
        while seq < len(items):
            item = items[seq]
            if item.command == M.MAV_CMD_DO_JUMP:
                target, repeats = int(item.param1), int(item.param2)
                if jumps_followed >= MAX_JUMPS_PER_SEARCH or (repeats < 0 and seq in jumps_seen):
                    before.clear()  # no NAV item within reach: the mission ends, as ArduPilot's does
                    break
                jumps_seen.add(seq)
                done = self._jumps.get(seq, 0)
                if 1 <= target < len(items) and (repeats < 0 or done < repeats):
                    self._jumps[seq] = done + 1
                    jumps_followed += 1
                    seq = target
                    continue
                seq += 1
                continue
            if is_nav(item.command):
                self.nav_seq = seq
                self._nav = {"started": False}
                self._synced_seq = seq
                self.pilot.set_current(seq)
                self.queue = list(before.items())
                follow = seq + 1
                while follow < len(items) and not is_nav(items[follow].command) \
                        and items[follow].command != M.MAV_CMD_DO_JUMP:
                    self.queue.append((follow, items[follow]))
                    follow += 1
                return True
            before.setdefault(seq, item)
            seq += 1
        for item in before.values():
            if not M.MAV_CMD_CONDITION_DELAY <= item.command <= M.MAV_CMD_CONDITION_LAST:
                self.pilot.do_command(item)
        self.complete = True
        self.nav_seq = None
        return False

    # --- DO and CONDITION items ------------------------------------------------------------------
    def _run_queue(self, s, dt: float) -> None:
        while self.queue:
            seq, item = self.queue[0]
            if M.MAV_CMD_CONDITION_DELAY <= item.command <= M.MAV_CMD_CONDITION_LAST:
                if not self._condition(seq, item, s, dt):
                    return
            else:
                self.pilot.do_command(item)
            self.queue.pop(0)
            self._cond = {}

    def _condition(self, seq: int, item: MissionItem, s, dt: float) -> bool:
        cond = self._cond
        if cond.get("seq") != seq:
            cond.clear()
            cond.update(seq=seq, elapsed=0.0)
            if item.command == M.MAV_CMD_CONDITION_YAW:
                self.pilot.condition_yaw(item.param1, item.param2, item.param3, item.param4)
        cond["elapsed"] += dt
        if item.command == M.MAV_CMD_CONDITION_DELAY:
            return cond["elapsed"] >= item.param1
        if item.command == M.MAV_CMD_CONDITION_DISTANCE:
            target = self._nav.get("target")
            return target is None or distance_m(s.lat, s.lon, target[0], target[1]) <= item.param1
        if item.command == M.MAV_CMD_CONDITION_YAW:
            return self.pilot.yaw_reached()
        return True

    # --- NAV items -------------------------------------------------------------------------------
    def _nav_step(self, item: MissionItem, s, dt: float) -> tuple[Setpoint | None, bool]:
        nav = self._nav
        cmd = item.command
        pilot = self.pilot
        if not nav["started"]:
            nav.update(started=True, elapsed=0.0, arrived=False, turned=0.0, last_bearing=None)
            nav["target"] = item_location(item, s)
            if cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
                pilot.rtl.begin(s)
            elif cmd == M.MAV_CMD_NAV_TAKEOFF:
                nav["target"] = (s.lat, s.lon, nav["target"][2])
        lat, lon, alt = nav["target"]
        speed = pilot.speed_ms
        if cmd in (M.MAV_CMD_NAV_WAYPOINT, M.MAV_CMD_NAV_SPLINE_WAYPOINT):
            radius = item.param2 if item.param2 > 0 else pilot.accept_radius_m()
            if not nav["arrived"] and pilot.at(lat, lon, alt, radius):
                nav["arrived"] = True
            if nav["arrived"]:
                nav["elapsed"] += dt
                done = pilot.settings.fixed_wing or nav["elapsed"] >= item.param1
                return Setpoint(Kind.HOLD, lat, lon, alt, speed), done
            return Setpoint(Kind.GOTO, lat, lon, alt, speed, radius_m=0.0), False
        if cmd in (M.MAV_CMD_NAV_TAKEOFF, M.MAV_CMD_NAV_VTOL_TAKEOFF):
            return pilot.takeoff_setpoint(alt), pilot.takeoff_done(alt)
        if cmd in (M.MAV_CMD_NAV_LAND, M.MAV_CMD_NAV_VTOL_LAND):
            return pilot.land_setpoint(lat, lon), pilot.landed_after_landing()
        if cmd == M.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return pilot.rtl.tick(s, dt), pilot.rtl.done
        if cmd == M.MAV_CMD_NAV_LOITER_UNLIM:
            return Setpoint(Kind.HOLD, lat, lon, alt, speed), False
        if cmd == M.MAV_CMD_NAV_LOITER_TO_ALT:
            done = abs(s.alt_amsl_m - alt) <= ALT_TOLERANCE_M and pilot.at(lat, lon, alt, pilot.loiter_radius_m() * 1.5)
            return Setpoint(Kind.HOLD, lat, lon, alt, speed), done
        if cmd == M.MAV_CMD_NAV_DELAY:
            nav["elapsed"] += dt
            return Setpoint(Kind.HOLD, s.lat, s.lon, s.alt_amsl_m), nav["elapsed"] >= item.param1
        if cmd in (M.MAV_CMD_NAV_LOITER_TIME, M.MAV_CMD_NAV_LOITER_TURNS):
            radius = min(abs(item.param3), MAX_LOITER_RADIUS_M) or pilot.loiter_radius_m()
            direction = -1 if item.param3 < 0 else 1
            if not nav["arrived"]:
                if pilot.at(lat, lon, alt, radius * 1.2 + pilot.accept_radius_m()):
                    nav["arrived"] = True
                else:
                    return Setpoint(Kind.GOTO, lat, lon, alt, speed), False
            nav["elapsed"] += dt
            if cmd == M.MAV_CMD_NAV_LOITER_TIME:
                return self._orbit(s, lat, lon, alt, radius, direction), nav["elapsed"] >= item.param1
            return self._orbit(s, lat, lon, alt, radius, direction), nav["turned"] >= 360.0 * min(max(item.param1, 0.0), MAX_TURNS)
        return None, True

    def _orbit(self, s, lat: float, lon: float, alt: float, radius: float, direction: int) -> Setpoint:
        nav = self._nav
        bearing = bearing_deg(lat, lon, s.lat, s.lon)
        if nav["last_bearing"] is not None:
            nav["turned"] += abs(wrap_180(bearing - nav["last_bearing"]))
        nav["last_bearing"] = bearing
        if self.pilot.settings.fixed_wing:
            return Setpoint(Kind.HOLD, lat, lon, alt, self.pilot.speed_ms, radius_m=radius, direction=direction)
        ahead = math.radians(bearing + direction * ORBIT_LEAD_DEG)
        plat, plon = offset(lat, lon, radius * math.cos(ahead), radius * math.sin(ahead))
        return Setpoint(Kind.GOTO, plat, plon, alt, self.pilot.speed_ms)
