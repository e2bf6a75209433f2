"""Failsafes: GCS heartbeat loss, low and critical battery, fence breach. Pure decisions.

`Failsafes.check(...)` looks at the state once per autopilot tick and returns `Event`s (a
STATUSTEXT and an optional action: a mode name, or DISARM). Each failsafe fires once when its
condition starts and is reported cleared when it ends, as ArduPilot's do:

- GCS: armed, the ground station (SYSID_MYGCS) has been heard at least once, and nothing for
  `gcs_timeout_s` of real time (the link runs in real time whatever the speedup). On the
  ground the action is DISARM. Cleared when its heartbeat returns.
- Battery: voltage below BATT_LOW_VOLT / BATT_CRT_VOLT for BATT_LOW_TIMER seconds (simulated
  time; ArduPilot's AP_BattMonitor filters a sagging voltage the same way) or remaining below
  BATT_LOW_MAH / BATT_CRT_MAH at once (0 disables each), while armed; critical supersedes low;
  never cleared until disarmed (a battery does not recover).
- Fence: armed, enabled, outside (gcsd.vehicle.autopilot.fence); breach count and time kept for
  FENCE_STATUS in the state.
- Radio (RC): `rc_lost` (gcsd.vehicle.types.rc: overrides lapsed after being used, or throttle
  below FS_THR_VALUE) while armed and the vehicle's throttle failsafe enabled: "Radio
  Failsafe", the vehicle's action (DISARM on the ground); "Radio Failsafe Cleared" when RC
  returns.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.autopilot import fence
from gcsd.vehicle.autopilot.settings import DISARM, Settings


@dataclass(frozen=True)
class Event:
    severity: int
    text: str
    action: str | None = None


class Failsafes:
    def __init__(self) -> None:
        self.gcs_lost = False
        self.battery_level = 0  # 0 ok, 1 low, 2 critical
        self.fence_breached: set[int] = set()
        self.radio_lost = False
        self._volts_low_since: dict[str, float] = {}  # "low" / "critical" -> simulated time

    def check(self, s, settings: Settings, params, gcs_last_seen_s: float | None, now: float,
              fence_items, sim_time_ms: int, rc_lost: bool = False) -> list[Event]:
        events: list[Event] = []
        if not s.armed:
            self.battery_level = 0
            self._volts_low_since = {}
            self.fence_breached = set()
        events += self._gcs(s, settings, gcs_last_seen_s, now)
        events += self._radio(s, settings, rc_lost)
        if s.armed:
            events += self._battery(s, settings, params)
            if "FENCE_ENABLE" in params:
                events += self._fence(s, settings, params, fence_items, sim_time_ms)
        s.failsafe = "GCS" if self.gcs_lost else ("Radio" if self.radio_lost else (
            "Battery" if self.battery_level else ("Fence" if self.fence_breached else None)))
        return events

    def _gcs(self, s, settings: Settings, last_seen: float | None, now: float) -> list[Event]:
        if last_seen is None or settings.gcs_failsafe is None:
            self.gcs_lost = False
            return []
        lost = now - last_seen > settings.gcs_timeout_s
        if lost and not self.gcs_lost and s.armed:
            self.gcs_lost = True
            action = DISARM if s.on_ground else settings.gcs_failsafe
            return [Event(M.MAV_SEVERITY_CRITICAL, "GCS Failsafe", action)]
        if not lost and self.gcs_lost:
            self.gcs_lost = False
            return [Event(M.MAV_SEVERITY_INFO, "GCS Failsafe Cleared")]
        return []

    def _radio(self, s, settings: Settings, rc_lost: bool) -> list[Event]:
        if settings.radio_failsafe is None:
            self.radio_lost = False
            return []
        if rc_lost and not self.radio_lost and s.armed:
            self.radio_lost = True
            action = DISARM if s.on_ground else settings.radio_failsafe
            return [Event(M.MAV_SEVERITY_WARNING, "Radio Failsafe", action)]
        if not rc_lost and self.radio_lost:
            self.radio_lost = False
            return [Event(M.MAV_SEVERITY_INFO, "Radio Failsafe Cleared")]
        return []

    def _battery(self, s, settings: Settings, params) -> list[Event]:
        if "BATT_LOW_VOLT" not in params or ("BATT_MONITOR" in params and params.get("BATT_MONITOR") == 0):
            return []  # no battery monitor: nothing to fail
        get = params.get
        volts, left = s.battery_voltage_v, s.capacity_mah - s.consumed_mah
        timer_s = float(get("BATT_LOW_TIMER")) if "BATT_LOW_TIMER" in params else 0.0

        def volts_below(level: str, limit: float) -> bool:  # held for BATT_LOW_TIMER
            if not (0 < limit and volts < limit):
                self._volts_low_since.pop(level, None)
                return False
            since = self._volts_low_since.setdefault(level, s.time_s)
            return s.time_s - since >= timer_s

        critical = volts_below("critical", get("BATT_CRT_VOLT")) or \
            (0 < get("BATT_CRT_MAH") and left < get("BATT_CRT_MAH"))
        low = volts_below("low", get("BATT_LOW_VOLT")) or \
            (0 < get("BATT_LOW_MAH") and left < get("BATT_LOW_MAH"))
        level = 2 if critical else (1 if low else 0)
        if level <= self.battery_level:
            return []
        self.battery_level = level
        word = "critical" if level == 2 else "low"
        action = settings.battery_critical if level == 2 else settings.battery_low
        text = f"Battery 1 is {word} {volts:.2f}V used {s.consumed_mah:.0f} mAh"
        return [Event(M.MAV_SEVERITY_CRITICAL, text, action)]

    def _fence(self, s, settings: Settings, params, items, sim_time_ms: int) -> list[Event]:
        cfg = fence.FenceConfig.from_params(params.get)
        if not cfg.enabled:
            self.fence_breached = set()
            return []
        now_breached = fence.breaches(s, cfg, items)
        new = now_breached - self.fence_breached
        self.fence_breached = now_breached
        s.fence_breach_type = fence.breach_code(now_breached)
        if not new:
            return []
        s.fence_breach_count = (s.fence_breach_count + 1) & 0xFFFF
        s.fence_breach_time_ms = sim_time_ms
        return [Event(M.MAV_SEVERITY_CRITICAL, f"Fence Breach: {fence.describe(new)}", settings.fence_action)]
