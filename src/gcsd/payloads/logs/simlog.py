"""The simulated vehicle's DataFlash log: what ArduPilot would write while armed.

`FlightRecorder` is pure: it reads a `VehicleState` and returns bytes to append.

- `start(time_us, wall_s, state, params, firmware)`: the header (FMT, UNIT, MULT, FMTU), one MSG
  per firmware banner line, one PARM per parameter (name, value, default), the current MODE.
- `sample(now, time_us, wall_s, state)`: when a sample is due (every 1/RATE_HZ s) GPS, ATT and
  CTUN, and BAT every BAT_EVERY-th sample; a MODE record whenever the mode changed; b"" when
  nothing is due. `next_sample_s` is the deadline.
- `text(time_us, text)`: a MSG record (what the vehicle said in STATUSTEXT).

GPS carries GPS week and milliseconds computed from the wall clock (UTC + leap seconds), which
is how DFReader sets a log's clock, and the altitude AMSL; CTUN the altitude above home.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

from gcsd.payloads.logs.dataflash import DataFlashWriter, RecordFormat
from gcsd.vehicle.sim.state import VehicleState

RATE_HZ = 5.0
BAT_EVERY = 5  # BAT at 1 Hz
GPS_EPOCH_UNIX_S = 315964800  # 1980-01-06
GPS_LEAP_S = 18
WEEK_S = 7 * 86400

FORMATS = (
    RecordFormat(64, "PARM", "QNff", ("TimeUS", "Name", "Value", "Default"), "s---", "F---"),
    RecordFormat(65, "MODE", "QMBB", ("TimeUS", "Mode", "ModeNum", "Rsn"), "s---", "F---"),
    RecordFormat(66, "MSG", "QZ", ("TimeUS", "Message"), "s-", "F-"),
    RecordFormat(67, "GPS", "QBBIHBcLLeffffB",
                 ("TimeUS", "I", "Status", "GMS", "GWk", "NSats", "HDop", "Lat", "Lng", "Alt", "Spd", "GCrs",
                  "VZ", "Yaw", "U"), "s#-s-S-DUmnhnh-", "F--C--BGGB000--"),
    RecordFormat(68, "ATT", "QccccCCCCB",
                 ("TimeUS", "DesRoll", "Roll", "DesPitch", "Pitch", "DesYaw", "Yaw", "ErrRP", "ErrYaw", "AEKF"),
                 "sddddhhdh-", "FBBBBBBBB-"),
    RecordFormat(69, "BAT", "QBfffffcf",
                 ("TimeUS", "Inst", "Volt", "VoltR", "Curr", "CurrTot", "EnrgTot", "Temp", "Res"),
                 "s#vvAaJOw", "F-0000000"),
    RecordFormat(70, "CTUN", "Qffffff", ("TimeUS", "ThO", "DAlt", "Alt", "BAlt", "CRt", "Spd"),
                 "s-mmmnn", "F000000"),
)


def gps_time(wall_s: float) -> tuple[int, int]:
    """(week, milliseconds of the week) of GPS time at a Unix time."""
    gps_s = wall_s - GPS_EPOCH_UNIX_S + GPS_LEAP_S
    week = int(gps_s // WEEK_S)
    return week, round((gps_s - week * WEEK_S) * 1000) % (WEEK_S * 1000)


class FlightRecorder:
    def __init__(self, modes: dict[int, str]) -> None:
        self.writer = DataFlashWriter(FORMATS)
        self.modes = modes
        self.next_sample_s = 0.0
        self._samples = 0
        self._mode: int | None = None

    def start(self, now: float, time_us: int, wall_s: float, state: VehicleState,
              params: Iterable[tuple[str, float, float]], firmware: Iterable[str]) -> bytes:
        w = self.writer
        out = [w.header(time_us)]
        out += [w.record("MSG", time_us, line) for line in firmware]
        out += [w.record("PARM", time_us, name, value, default) for name, value, default in params]
        self._mode = None
        self._samples = 0
        self.next_sample_s = now
        out.append(self._mode_record(time_us, state))
        return b"".join(out)

    def _mode_record(self, time_us: int, state: VehicleState) -> bytes:
        self._mode = state.mode
        return self.writer.record("MODE", time_us, state.mode & 0xFF, state.mode & 0xFF, 1)

    def text(self, time_us: int, text: str) -> bytes:
        return self.writer.record("MSG", time_us, text)

    def sample(self, now: float, time_us: int, wall_s: float, state: VehicleState) -> bytes:
        if now < self.next_sample_s:
            return b""
        self.next_sample_s = max(self.next_sample_s + 1.0 / RATE_HZ, now)
        w, s = self.writer, state
        out = []
        if s.mode != self._mode:
            out.append(self._mode_record(time_us, s))
        week, week_ms = gps_time(wall_s)
        speed = math.hypot(s.vn_ms, s.ve_ms)
        course = math.degrees(math.atan2(s.ve_ms, s.vn_ms)) % 360.0
        yaw_deg = math.degrees(s.yaw_rad) % 360.0
        roll_deg, pitch_deg = math.degrees(s.roll_rad), math.degrees(s.pitch_rad)
        out.append(w.record("GPS", time_us, 0, s.gps_fix_type, week_ms, week, s.satellites, s.hdop, s.lat, s.lon,
                            s.alt_amsl_m, speed, course, s.vd_ms, yaw_deg, 1))
        out.append(w.record("ATT", time_us, roll_deg, roll_deg, pitch_deg, pitch_deg, yaw_deg, yaw_deg, 0, 0, 3))
        rel_alt = s.alt_amsl_m - s.home_alt_m
        target_alt = s.target[2] - s.home_alt_m if s.target is not None else rel_alt
        out.append(w.record("CTUN", time_us, s.throttle_pct / 100.0, target_alt, rel_alt, rel_alt, -s.vd_ms, speed))
        if self._samples % BAT_EVERY == 0:
            volts = s.battery_voltage_v
            out.append(w.record("BAT", time_us, 0, volts, volts, s.current_a, s.consumed_mah / 1000.0,
                                volts * s.consumed_mah * 3.6, 25.0, 0.0))
        self._samples += 1
        return b"".join(out)

