"""DataFlash records and the simulated flight recorder, read back by pymavlink's DFReader."""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from pymavlink import DFReader

from gcsd.payloads.logs.dataflash import DataFlashWriter, RecordFormat
from gcsd.payloads.logs.simlog import RATE_HZ, FlightRecorder, gps_time
from gcsd.vehicle.sim.state import VehicleState

WALL = 1_764_000_000.0


def read_all(tmp_path, data: bytes):
    path = tmp_path / "x.BIN"
    path.write_bytes(data)
    reader = DFReader.DFReader_binary(str(path))
    out = []
    while (m := reader.recv_match()) is not None:
        out.append(m)
    return out, reader


def test_records_round_trip_with_scaled_letters_and_units(tmp_path):
    fmt = RecordFormat(20, "TST", "QcLeNf", ("TimeUS", "Ang", "Lat", "Alt", "Txt", "F"), "sdDm-n", "FBGB-0")
    w = DataFlashWriter((fmt,))
    msgs, reader = read_all(tmp_path, w.header(0) + w.record("TST", 5, 12.34, -35.3632621, 584.25, "hello", 1.5))
    tst = next(m for m in msgs if m.get_type() == "TST")
    assert (tst.TimeUS, tst.Ang, tst.Alt, tst.Txt, tst.F) == (5, 12.34, 584.25, "hello", 1.5)
    assert tst.Lat == pytest.approx(-35.3632621, abs=1e-7)
    assert reader.formats[20].units[3] == "m"  # the FMTU was read


def test_out_of_range_and_non_finite_values_are_clamped_not_raised():
    fmt = RecordFormat(21, "CLMP", "Qbc", ("TimeUS", "B", "C"))
    w = DataFlashWriter((fmt,))
    rec = w.record("CLMP", 0, 1000, math.nan)
    assert rec[-3:] == bytes([127, 0, 0])


def test_a_format_that_does_not_match_its_columns_is_refused():
    with pytest.raises(ValueError):
        RecordFormat(22, "BAD", "Qf", ("TimeUS",))
    with pytest.raises(ValueError):
        DataFlashWriter((RecordFormat(128, "DUP", "Q", ("TimeUS",)),))


def test_gps_time_of_a_known_instant():
    # 2026-01-01 00:00:00 UTC: GPS week 2399, 345 618 s into it (leap seconds included)
    assert gps_time(1767225600.0) == (2399, 345_618_000)


def test_the_recorder_writes_a_flight_dfreader_reads_with_its_clock_and_altitude(tmp_path):
    s = VehicleState(lat=-35.36, lon=149.16, alt_amsl_m=584.0, home_lat=-35.36, home_lon=149.16, home_alt_m=584.0)
    rec = FlightRecorder({0: "STABILIZE", 4: "GUIDED", 9: "LAND"})
    data = rec.start(0.0, 0, WALL, s, [("SYSID_THISMAV", 1.0, 1.0)], ["ArduCopter V4.6.2 (gcsd)"])
    t = 0.0
    while t < 20.0:
        s.alt_amsl_m = 584.0 + min(t, 10.0)
        s.mode = 4 if t < 15 else 9
        data += rec.sample(t, int(t * 1e6), WALL + t, s)
        assert rec.sample(t, int(t * 1e6), WALL + t, s) == b""  # nothing due twice at one instant
        t += 0.01
    msgs, _reader = read_all(tmp_path, data)
    gps = [m for m in msgs if m.get_type() == "GPS"]
    assert len(gps) == pytest.approx(20 * RATE_HZ, abs=2)
    assert max(m.Alt for m in gps) == pytest.approx(594.0, abs=0.01)
    assert max(m.Alt for m in msgs if m.get_type() == "CTUN") == pytest.approx(10.0, abs=0.01)
    assert [m.Mode for m in msgs if m.get_type() == "MODE"] == [0, 4, 9]
    assert gps[0]._timestamp == pytest.approx(WALL, abs=1.0)  # DFReader's clock from GWk/GMS
    assert {"PARM", "MSG", "ATT", "BAT", "FMTU"} <= {m.get_type() for m in msgs}


def test_mavlogdump_reads_the_recorded_flight(tmp_path):
    """pymavlink's mavlogdump.py (what MAVExplorer's loader is built on) prints the flight."""
    script = shutil.which("mavlogdump.py", path=str(Path(sys.executable).parent)) or shutil.which("mavlogdump.py")
    if script is None:
        pytest.skip("mavlogdump.py is not installed")
    s = VehicleState(lat=-35.36, lon=149.16, alt_amsl_m=584.0, home_lat=-35.36, home_lon=149.16, home_alt_m=584.0)
    rec = FlightRecorder({0: "STABILIZE"})
    data = rec.start(0.0, 0, WALL, s, [], ["fw"])
    for i in range(10):
        s.alt_amsl_m = 584.0 + i
        data += rec.sample(i * 0.2, int(i * 0.2e6), WALL + i * 0.2, s)
    path = tmp_path / "f.BIN"
    path.write_bytes(data)
    out = subprocess.run([sys.executable, script, "--types", "GPS", "--format", "csv", str(path)],
                         capture_output=True, text=True, timeout=60, check=True).stdout.splitlines()
    header, rows = out[0].split(","), [line.split(",") for line in out[1:]]
    assert len(rows) == 10
    assert float(rows[-1][header.index("Alt")]) == pytest.approx(593.0)
