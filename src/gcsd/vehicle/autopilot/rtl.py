"""Return to launch: where to go, at what altitude, and what to do on arrival.

The destination is the nearest rally point within RALLY_LIMIT_KM (home too when
RALLY_INCL_HOME, or when there is no rally point). Phases, for a vehicle that hovers:
CLIMB to the RTL altitude (never descending to it), RETURN at that altitude, LOITER for
`rtl_loiter_s`, then FINAL: land (`rtl_final_alt_m` 0) or hover at the final height.
A fixed wing returns at the RTL altitude and circles the destination (RTL_RADIUS); a rover
drives there and stops. `done` becomes true on arrival (or on landing, for a vehicle that
lands), which is when a mission's NAV_RETURN_TO_LAUNCH completes.
"""

from __future__ import annotations

from gcsd.vehicle.mission.items import MissionItem
from gcsd.vehicle.sim.geo import distance_m
from gcsd.vehicle.sim.state import Kind, Setpoint

CLIMB, RETURN, LOITER, FINAL, ARRIVED = "climb", "return", "loiter", "final", "arrived"


class Rtl:
    def __init__(self, pilot) -> None:
        self.pilot = pilot
        self.phase = ARRIVED
        self.dest = (0.0, 0.0, 0.0)
        self.done = False
        self._loiter_s = 0.0

    def begin(self, s) -> None:
        settings = self.pilot.settings
        lat, lon, dest_alt = self._destination(s)
        if settings.rtl_alt_m < 0:  # keep the current altitude (rover, blimp, plane RTL_ALTITUDE -1)
            alt, self.phase = s.alt_amsl_m, RETURN
        elif settings.fixed_wing:
            alt, self.phase = max(s.home_alt_m + settings.rtl_alt_m, dest_alt), RETURN
        else:  # climb first, never descend to the RTL altitude
            alt = max(s.home_alt_m + settings.rtl_alt_m, dest_alt, s.alt_amsl_m)
            self.phase = CLIMB if s.alt_amsl_m < alt - 0.5 else RETURN
        self.dest = (lat, lon, alt)
        self.done = False
        self._loiter_s = 0.0

    def _destination(self, s) -> tuple[float, float, float]:
        params = self.pilot.params
        home = (s.home_lat, s.home_lon, s.home_alt_m)
        points: list[tuple[float, float, float]] = [self._rally_location(item, s) for item in self.pilot.rally_items()]
        limit_m = float(params.get("RALLY_LIMIT_KM")) * 1000.0 if "RALLY_LIMIT_KM" in params else 0.0
        if limit_m > 0:
            points = [p for p in points if distance_m(s.lat, s.lon, p[0], p[1]) <= limit_m]
        if not points or ("RALLY_INCL_HOME" in params and params.get("RALLY_INCL_HOME")):
            points.append(home)
        return min(points, key=lambda p: distance_m(s.lat, s.lon, p[0], p[1]))

    @staticmethod
    def _rally_location(item: MissionItem, s) -> tuple[float, float, float]:
        from gcsd.vehicle.autopilot.mission import item_location
        return item_location(item, s)

    def tick(self, s, dt: float) -> Setpoint:
        settings = self.pilot.settings
        lat, lon, alt = self.dest
        speed = settings.rtl_speed_ms or self.pilot.speed_ms
        if self.phase == CLIMB:
            if s.alt_amsl_m >= alt - 0.5:
                self.phase = RETURN
            return Setpoint(Kind.GOTO, s.lat, s.lon, alt, speed)
        if self.phase == RETURN:
            if self.pilot.at(lat, lon, alt, self.pilot.accept_radius_m() if not settings.fixed_wing
                             else self.pilot.loiter_radius_m() * 1.5, check_alt=not settings.fixed_wing):
                self.phase = LOITER
                if not settings.rtl_lands:
                    self.done = True
            else:
                return Setpoint(Kind.GOTO, lat, lon, alt, speed, radius_m=None if settings.fixed_wing else 0.0)
        radius = settings.extra.get("rtl_radius_m")
        if self.phase == LOITER:
            self._loiter_s += dt
            if settings.rtl_lands and self._loiter_s >= settings.rtl_loiter_s:
                self.phase = FINAL
            return Setpoint(Kind.HOLD, lat, lon, alt, speed, radius_m=radius)
        if settings.rtl_final_alt_m > 0:
            self.done = True
            return Setpoint(Kind.HOLD, lat, lon, s.home_alt_m + settings.rtl_final_alt_m, speed)
        if s.on_ground:
            self.done = True
        return Setpoint(Kind.LAND, lat, lon, s.ground_m)
