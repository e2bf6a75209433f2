"""Flight logs with real clients against the real daemon (a subprocess): MAVProxy's `log list` /
`log download` and `ftp get logs/...`, MAVSDK's log_files `get_entries` / `download_log_file`
and its ftp plugin each fetch the same bytes as the file gcsd keeps.

The log is a real DataFlash file (the simulated flight recorder's, a few hundred kB, not a
multiple of LOG_DATA's 90 bytes) placed in the daemon's log directory before it starts, with
its start time as its mtime (what LOG_ENTRY.time_utc reports).
"""

from __future__ import annotations

import asyncio
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from pymavlink import DFReader

from gcsd.payloads.logs.simlog import FlightRecorder
from gcsd.vehicle.sim.state import VehicleState

pytest.importorskip("MAVProxy", reason="MAVProxy is a test extra: pip install -e .[test]")
pytest.importorskip("mavsdk.asyncio", reason="mavsdk is a test extra: pip install -e .[test]")

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.ftp import FtpAsync
from mavsdk.asyncio.plugins.log_files import LogFilesAsync

from .test_ftp_interop import MavProxy, wait_until

pytestmark = pytest.mark.interop

START_UTC = 1_767_225_600  # 2026-01-01 00:00:00


def make_log(seconds: float = 600.0) -> bytes:
    s = VehicleState(lat=-35.36, lon=149.16, alt_amsl_m=584.0, home_lat=-35.36, home_lon=149.16, home_alt_m=584.0)
    rec = FlightRecorder({0: "STABILIZE", 4: "GUIDED"})
    parts = [rec.start(0.0, 0, START_UTC, s, [(f"PARAM_{i}", float(i), 0.0) for i in range(500)], ["interop"])]
    t = 0.0
    while t < seconds:
        t += 0.2
        s.alt_amsl_m = 584.0 + 10.0 * (t / seconds)
        parts.append(rec.sample(t, int(t * 1e6), START_UTC + t, s))
    data = b"".join(parts)
    return data if len(data) % 90 else data + b"\0"


@pytest.fixture
def logged(gcsd_daemon, tmp_path):
    """A daemon whose log directory holds one real log; returns (daemon, the log's bytes)."""
    data = make_log()
    logs = tmp_path / "gcsd" / "state" / "logs"
    logs.mkdir(parents=True)
    (logs / "00000001.BIN").write_bytes(data)
    os.utime(logs / "00000001.BIN", (START_UTC, START_UTC))
    return gcsd_daemon(), data


def test_mavproxy_log_list_log_download_and_ftp_get_fetch_the_log(logged, spawn, tmp_path):
    daemon, data = logged
    mp = MavProxy(spawn, tmp_path / "mp", daemon.port("gcs"), daemon, modules="log,ftp")
    entry = mp.run("log list", r"Log 1\s+numLogs 1 lastLog 1 size (\d+)", "the log's entry")
    assert int(entry[1]) == len(data)
    got = tmp_path / "mp" / "by_log.bin"
    mp.run(f"log download 1 {got}", rf"Finished downloading {got} \({len(data)} bytes", "the log download",
           timeout_s=30.0)
    wait_until(lambda: got.exists() and got.read_bytes() == data, 10.0, "the log download differs", daemon)
    by_ftp = tmp_path / "mp" / "by_ftp.bin"
    mp.run(f"ftp get logs/00000001.BIN {by_ftp}", rf"Wrote {len(data)} bytes to", "the FTP download",
           timeout_s=30.0)
    wait_until(lambda: by_ftp.exists() and by_ftp.read_bytes() == data, 10.0, "the FTP download differs", daemon)
    reader = DFReader.DFReader_binary(str(got))
    assert reader.recv_match(type="GPS") is not None


async def test_mavsdk_log_files_and_ftp_fetch_the_log(logged, tmp_path):
    daemon, data = logged
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    await mavsdk.add_any_connection(f"udpout://127.0.0.1:{daemon.port('gcs')}")
    system = await mavsdk.first_autopilot(timeout_s=10.0)
    assert system is not None, "MAVSDK found no autopilot"
    log_files, ftp = LogFilesAsync(system), FtpAsync(system)
    try:
        entries = await asyncio.wait_for(log_files.get_entries(), 10.0)
        assert [e.size_bytes for e in entries] == [len(data)]
        assert entries[0].date.startswith("2026-01-01T00:00:00")
        target = tmp_path / "mavsdk" / "by_log.bin"
        target.parent.mkdir()
        start = time.monotonic()
        async for _result, _progress in log_files.download_log_file(entries[0], str(target)):
            assert time.monotonic() - start < 60.0
        assert target.read_bytes() == data
        (tmp_path / "ftp").mkdir()
        async for _ in ftp.download("/logs/00000001.BIN", str(tmp_path / "ftp"), True):
            pass
        assert (tmp_path / "ftp" / "00000001.BIN").read_bytes() == data
    finally:
        log_files.destroy()
        del mavsdk


def test_the_same_files_are_what_gcsd_logs_lists(logged):
    daemon, data = logged
    config = Path(daemon.config["state_dir"]).parents[1] / "gcsd.yaml"
    pythonpath = [*os.environ.get("PYTHONPATH", "").split(os.pathsep), str(Path(__file__).parents[2] / "src")]
    out = subprocess.run([sys.executable, "-m", "gcsd", "logs", "-c", str(config)], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(pythonpath)}, timeout=30, check=False)
    assert out.returncode == 0, out.stderr
    assert f"   1 {len(data):>12}  2026-01-01 00:00:00" in out.stdout
