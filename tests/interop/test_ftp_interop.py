"""MAVLink FTP with real clients: MAVProxy's `ftp`, `param` and `wp`/`fence` modules, and MAVSDK's
`ftp` plugin, against the real daemon (a subprocess) whose FTP root is `<state_dir>/ftp`.

MAVProxy runs headless as in test_mavproxy.py (commands on stdin). Its console is the
observable: `ftp list` prints "   NAME\tSIZE" and " D NAME", `ftp get` "Wrote N bytes to F",
`ftp put` "Sent file of length N", `ftp crc` "crc: NAME 0xCRC"; mkdir, rename and rm print only
on failure, so the test looks at the FTP root. `param fetch` with the ftp module loaded asks for
`@PARAM/param.pck?withdefaults=1` ("Getting ..." with `ftp set debug 2`) and ends with "Received
N parameters (ftp)"; `wp ftp` and `fence ftp` print one line per item read from @MISSION.

MAVSDK (4.x, ctypes) lists, downloads (burst), uploads, removes and compares a CRC32 it computes
itself. Its Python binding does not expose Mavsdk::set_timeout_s; over the lossy link it is set
through the C library to 50 ms (the FTP spec's client guidance), since MAVSDK uploads lock-step
and would otherwise wait its default 0.5 s for every lost packet.

The lossy link is a UDP proxy dropping a seeded 10 % of datagrams in each direction; the file
round-tripped through it is 250 kB in CI (about 1 000 datagrams each way) and 2 MB with
GCSD_LONG_TESTS=1 (minutes: the figures in bench/RESULTS.md).
"""

from __future__ import annotations

import asyncio
import ctypes
import os
import random
import re
import select
import socket
import sys
import threading
import time
import zlib
from pathlib import Path

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission import wpl
from gcsd.vehicle.mission.items import MissionItem

pytest.importorskip("MAVProxy", reason="MAVProxy is a test extra: pip install -e .[test]")
pytest.importorskip("mavsdk.asyncio", reason="mavsdk is a test extra: pip install -e .[test]")

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.ftp import FtpAsync

from .conftest import mavproxy_script as _mavproxy_script

pytestmark = pytest.mark.interop

DETECT_WAIT_S = 10.0
OP_WAIT_S = 10.0
LOSSY_WAIT_S = 120.0
LOSSY_BYTES = 2_000_000 if os.environ.get("GCSD_LONG_TESTS") else 250_000


def crc32_ardupilot(data: bytes) -> int:
    """CRC-32 as ArduPilot computes it (seed 0, no final XOR), from zlib's standard one."""
    return zlib.crc32(data, 0xFFFFFFFF) ^ 0xFFFFFFFF


def ftp_root(daemon) -> Path:
    return Path(daemon.config["state_dir"]) / "ftp"


def wait_until(condition, timeout_s: float, what: str, daemon) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.05)
    pytest.fail(f"{what} within {timeout_s} s\n{daemon.describe()}", pytrace=False)


# ---------------------------------------------------------------------------------------------
# MAVProxy


class MavProxy:
    def __init__(self, spawn, cwd: Path, port: int, daemon, modules: str | None, cmds: str | None = None):
        cwd.mkdir(parents=True, exist_ok=True)
        argv = [sys.executable, _mavproxy_script(), f"--master=udpout:127.0.0.1:{port}", "--no-state"]
        if modules is not None:
            argv.append(f"--default-modules={modules}")
        if cmds is not None:
            argv.append(f"--cmd={cmds}")
        self.process = spawn(argv, name="mavproxy", cwd=cwd, env_overrides={"HOME": str(cwd)})
        self.daemon = daemon
        self.expect(r"Detected vehicle 1:1 on link 0", DETECT_WAIT_S, 0, "the vehicle")

    def expect(self, pattern: str, timeout_s: float, since: int, what: str) -> re.Match:
        found = self.process.output.wait_for(pattern, timeout_s, since=since)
        if found is None:
            pytest.fail(
                f"MAVProxy did not print {what} (/{pattern}/) within {timeout_s} s\n"
                f"{self.process.describe()}\n\n{self.daemon.describe()}",
                pytrace=False,
            )
        return found[2]

    def run(self, command: str, pattern: str, what: str, timeout_s: float = OP_WAIT_S) -> re.Match:
        since = len(self.process.output)
        self.process.send_line(command)
        return self.expect(pattern, timeout_s, since, what)

    def lines_since(self, since: int) -> list[str]:
        return [line for _, line in self.process.output.lines(since)]

    def stop(self) -> None:
        self.process.stop(5.0, end_of_input_first=True)


def test_mavproxy_ftp_list_get_put_crc_mkdir_rename_rm(spawn, gcsd_daemon, tmp_path):
    daemon = gcsd_daemon()
    root = ftp_root(daemon)
    blob = os.urandom(51_200)
    (root / "blob.bin").write_bytes(blob)
    (root / "hello.txt").write_bytes(b"hello, world")
    (root / "logs").mkdir()
    local = tmp_path / "local.bin"
    local.write_bytes(os.urandom(30_000))
    mp = MavProxy(spawn, tmp_path / "mp", daemon.port("gcs"), daemon, modules="ftp")

    since = len(mp.process.output)
    mp.run("ftp list /", r"Total size", "the end of the listing")
    listing = "\n".join(mp.lines_since(since))
    for entry in ("   blob.bin\t51200", "   hello.txt\t12", " D logs", " D @PARAM", " D @MISSION"):
        assert entry in listing, f"{entry!r} not in the listing:\n{listing}"

    got = tmp_path / "got.bin"
    mp.run(f"ftp get blob.bin {got}", r"Wrote 51200 bytes to", "the download")
    # MAVProxy prints before its file object is closed (flushed): wait for the content
    wait_until(lambda: got.read_bytes() == blob, OP_WAIT_S, "the downloaded file differs", daemon)

    crc = mp.run("ftp crc blob.bin", r"crc: blob.bin 0x([0-9a-f]{8})", "the CRC")
    assert int(crc[1], 16) == crc32_ardupilot(blob)

    mp.process.send_line("ftp mkdir up")
    wait_until(lambda: (root / "up").is_dir(), OP_WAIT_S, "ftp mkdir made no directory", daemon)

    mp.run(f"ftp put {local} up/local.bin", r"Sent file of length 30000", "the upload")
    uploaded = root / "up" / "local.bin"
    wait_until(uploaded.exists, OP_WAIT_S, "the uploaded file is missing", daemon)
    assert (root / "up" / "local.bin").read_bytes() == local.read_bytes()

    mp.process.send_line("ftp rename up/local.bin up/renamed.bin")
    renamed = root / "up" / "renamed.bin"
    wait_until(renamed.exists, OP_WAIT_S, "ftp rename renamed nothing", daemon)
    assert not (root / "up" / "local.bin").exists()

    mp.process.send_line("ftp rm hello.txt")
    wait_until(lambda: not (root / "hello.txt").exists(), OP_WAIT_S, "ftp rm removed nothing", daemon)
    mp.process.send_line("ftp rm up/renamed.bin")
    wait_until(lambda: not renamed.exists(), OP_WAIT_S, "ftp rm removed nothing", daemon)
    mp.process.send_line("ftp rmdir up")
    wait_until(lambda: not (root / "up").exists(), OP_WAIT_S, "ftp rmdir removed nothing", daemon)
    assert "failed" not in "\n".join(mp.lines_since(0)).lower()


def _list_download(port: int, timeout_s: float = 10.0) -> dict[str, float]:
    """Every parameter by PARAM_REQUEST_LIST, as a pymavlink ground station gets it."""
    conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=250, source_component=190)
    conn.mav = M.MAVLink(conn, srcSystem=250, srcComponent=190)
    try:
        by_index, count = {}, None
        deadline = time.monotonic() + timeout_s
        last_request = 0.0
        while time.monotonic() < deadline and (count is None or len(by_index) < count):
            if time.monotonic() - last_request > 1.0:
                conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                if count is None:
                    conn.mav.param_request_list_send(1, 1)
                else:
                    # ArduCopter's 1 000 values come one per datagram: a client busy elsewhere loses
                    # some from its socket buffer, so ask again for up to 100 at a time
                    for index in sorted(set(range(count)) - set(by_index))[:100]:
                        conn.mav.param_request_read_send(1, 1, b"", index)
                last_request = time.monotonic()
            msg = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=0.2)
            if msg is not None and (msg.get_srcSystem(), msg.get_srcComponent()) == (1, 1):
                count = msg.param_count
                if 0 <= msg.param_index < count:
                    name = msg.param_id if isinstance(msg.param_id, str) else msg.param_id.decode()
                    by_index[msg.param_index] = (name.split("\0")[0], msg.param_value)
        assert count is not None and len(by_index) == count, f"list download: {len(by_index)} of {count}"
        return dict(by_index.values())
    finally:
        conn.close()


def test_mavproxy_fetches_parameters_through_param_pck_with_defaults_equal_to_the_list(
    spawn, gcsd_daemon, tmp_path
):
    daemon = gcsd_daemon()
    expected = _list_download(daemon.port("gcs"))
    mp = MavProxy(spawn, tmp_path / "mp", daemon.port("gcs"), daemon, modules=None, cmds="ftp set debug 2")
    since = len(mp.process.output)
    mp.process.send_line("param fetch")
    mp.expect(r"Getting @PARAM/param\.pck\?withdefaults=1 as", OP_WAIT_S, since, "the param.pck request")
    received = mp.expect(r"Received (\d+) parameters \(ftp\)", OP_WAIT_S, since, "the parameters over FTP")
    assert int(received[1]) == len(expected)
    saved = tmp_path / "mavproxy.parm"
    mp.run(f"param save {saved}", r"Saved \d+ parameters to", "the saved parameters")
    got = {}
    for line in saved.read_text().splitlines():
        name, value = line.split()
        got[name] = float(value)
    assert set(got) == set(expected)
    for name, value in expected.items():
        assert got[name] == pytest.approx(value, rel=1e-6, abs=1e-6), name

    # and back: `param ftpload` writes a param.pck, which sets the parameters when the session ends
    wanted = {"SR0_EXTRA1": 3.0, "BATT_CAPACITY": 4321.0}
    assert all(expected[name] != value for name, value in wanted.items())
    upload = tmp_path / "changes.parm"
    upload.write_text("".join(f"{name} {value:g}\n" for name, value in wanted.items()))
    mp.run(f"param ftpload {upload}", r"Parameter upload done", "the param.pck upload")
    wait_until(lambda: all(_list_download(daemon.port("gcs"))[n] == v for n, v in wanted.items()),
               OP_WAIT_S, "the uploaded parameters did not take effect", daemon)


def test_mavproxy_wp_ftp_and_fence_ftp_read_the_plans(spawn, gcsd_daemon, tmp_path):
    state = tmp_path / "gcsd" / "state"  # where gcsd_daemon() puts the daemon's state
    state.mkdir(parents=True)
    home = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 0, 1, 0, 0, 0, 0,
                       -353632620, 1491652370, 584.0)
    mission = [home] + [
        MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0, 1, 0, 0, 0, 0,
                    -353632620 + 1000 * i, 1491652370 + 1000 * i, 20.0 + i)
        for i in range(1, 6)
    ]
    square = [(-353600000, 1491600000), (-353600000, 1491700000), (-353700000, 1491700000),
              (-353700000, 1491600000)]
    fence = [
        MissionItem(M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, M.MAV_FRAME_GLOBAL, 0, 1, 4, 0, 0, 0,
                    x, y, 0.0)
        for x, y in square
    ]
    (state / "mission.waypoints").write_text(wpl.dumps(mission))
    (state / "fence.waypoints").write_text(wpl.dumps(fence))
    daemon = gcsd_daemon()
    mp = MavProxy(spawn, tmp_path / "mp", daemon.port("gcs"), daemon, modules="ftp,wp,fence")

    since = len(mp.process.output)
    mp.process.send_line("wp ftp")
    last_waypoint = rf"(?:^|> ){M.MAV_CMD_NAV_WAYPOINT} \d+ -35\.3627620000 149\.1657370000 25\.0"
    mp.expect(last_waypoint, OP_WAIT_S, since, "the last waypoint read over FTP")
    rows = [line for line in mp.lines_since(since) if re.search(r"(?:^|> )\d+ \d+ -?\d+\.\d{10} ", line)]
    assert len(rows) == len(mission), rows
    assert "-35.3632620000 149.1652370000 584.0" in rows[0]  # item 0 is home

    since = len(mp.process.output)
    mp.process.send_line("fence ftp")
    vertex = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
    mp.expect(rf"(?:^|> ){vertex} \d+ -35\.3700000000 149\.1600000000", OP_WAIT_S, since,
              "the last fence vertex read over FTP")
    rows = [line for line in mp.lines_since(since) if re.search(rf"(?:^|> ){vertex} \d+ ", line)]
    assert len(rows) == len(fence), rows


# ---------------------------------------------------------------------------------------------
# MAVSDK


async def _mavsdk_ftp(port: int, timeout_s: float | None = None):
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    if timeout_s is not None:
        lib = mavsdk._mavsdk._lib  # Mavsdk::set_timeout_s, not wrapped by the Python binding
        lib.mavsdk_set_timeout_s.argtypes = [ctypes.c_void_p, ctypes.c_double]
        lib.mavsdk_set_timeout_s(mavsdk._mavsdk._handle, timeout_s)
    await mavsdk.add_any_connection(f"udpout://127.0.0.1:{port}")
    system = await mavsdk.first_autopilot(timeout_s=10.0)
    assert system is not None, "MAVSDK found no autopilot"
    return mavsdk, FtpAsync(system)


async def _download(ftp: FtpAsync, remote: str, local_dir: Path) -> None:
    local_dir.mkdir(parents=True, exist_ok=True)
    async for _ in ftp.download(remote, str(local_dir), True):
        pass


async def _upload(ftp: FtpAsync, local: Path, remote_dir: str) -> None:
    async for _ in ftp.upload(str(local), remote_dir):
        pass


async def test_mavsdk_lists_downloads_uploads_removes_and_compares_crc32(gcsd_daemon, tmp_path):
    daemon = gcsd_daemon()
    root = ftp_root(daemon)
    data = os.urandom(300_000)
    (root / "data.bin").write_bytes(data)
    (root / "sub").mkdir()
    local = tmp_path / "up.bin"
    local.write_bytes(os.urandom(100_000))
    mavsdk, ftp = await _mavsdk_ftp(daemon.port("gcs"))
    try:
        listing = await ftp.list_directory("/")
        entries = {(e.name, e.entry_type.name) for e in listing.entries}
        assert {("data.bin", "FILE"), ("sub", "DIRECTORY"), ("@PARAM", "DIRECTORY")} <= entries, entries
        sizes = {e.name: e.size_bytes for e in listing.entries}
        assert sizes["data.bin"] == len(data)

        await _download(ftp, "/data.bin", tmp_path / "dl")
        assert (tmp_path / "dl" / "data.bin").read_bytes() == data

        await _upload(ftp, local, "/sub")
        assert (root / "sub" / "up.bin").read_bytes() == local.read_bytes()
        assert await ftp.are_files_identical(str(local), "/sub/up.bin") is True
        assert await ftp.are_files_identical(str(local), "/data.bin") is False

        await ftp.remove_file("/sub/up.bin")
        assert not (root / "sub" / "up.bin").exists()
    finally:
        ftp.destroy()
        mavsdk.destroy()


# ---------------------------------------------------------------------------------------------
# A 10 % loss link


class LossyUdpProxy:
    """Forwards datagrams between one client and the daemon, dropping a seeded 10 % each way."""

    def __init__(self, target_port: int, loss: float = 0.10, seed: int = 5) -> None:
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.front.bind(("127.0.0.1", 0))
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.back.connect(("127.0.0.1", target_port))
        for sock in (self.front, self.back):
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
            sock.setblocking(False)
        self.rng = random.Random(seed)
        self.loss = loss
        self.client = None
        self.passed = self.dropped = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lossy-proxy", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        return self.front.getsockname()[1]

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self.front, self.back], [], [], 0.05)
            for sock in ready:
                while True:
                    try:
                        data, addr = sock.recvfrom(65536)
                    except (BlockingIOError, OSError):
                        break
                    if sock is self.front:
                        self.client = addr
                    if self.rng.random() < self.loss:
                        self.dropped += 1
                        continue
                    self.passed += 1
                    try:
                        if sock is self.front:
                            self.back.send(data)
                        elif self.client is not None:
                            self.front.sendto(data, self.client)
                    except OSError:
                        pass

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self.front.close()
        self.back.close()


@pytest.fixture
def lossy_proxy():
    proxies = []

    def start(port: int) -> LossyUdpProxy:
        proxy = LossyUdpProxy(port)
        proxies.append(proxy)
        return proxy

    yield start
    for proxy in proxies:
        proxy.close()


@pytest.mark.slow
def test_mavproxy_round_trips_a_file_through_a_10_percent_loss_link(spawn, gcsd_daemon, lossy_proxy, tmp_path):
    daemon = gcsd_daemon()
    root = ftp_root(daemon)
    data = os.urandom(LOSSY_BYTES)
    (root / "two.bin").write_bytes(data)
    proxy = lossy_proxy(daemon.port("gcs"))
    mp = MavProxy(spawn, tmp_path / "mp", proxy.port, daemon, modules="ftp")

    started = time.monotonic()
    mp.run(f"ftp get two.bin {tmp_path / 'got.bin'}", rf"Wrote {LOSSY_BYTES} bytes to", "the download",
           LOSSY_WAIT_S)
    got_s = time.monotonic() - started
    got = tmp_path / "got.bin"
    wait_until(lambda: got.read_bytes() == data, OP_WAIT_S, "the downloaded file differs", daemon)
    started = time.monotonic()
    mp.run(f"ftp put {tmp_path / 'got.bin'} back.bin", rf"Sent file of length {LOSSY_BYTES}", "the upload",
           LOSSY_WAIT_S)
    put_s = time.monotonic() - started
    wait_until(lambda: (root / "back.bin").exists() and (root / "back.bin").stat().st_size == LOSSY_BYTES,
               OP_WAIT_S, "the uploaded file is incomplete", daemon)
    assert (root / "back.bin").read_bytes() == data
    print(f"MAVProxy through 10 % loss: get {got_s:.1f} s, put {put_s:.1f} s; proxy dropped {proxy.dropped} "
          f"of {proxy.dropped + proxy.passed} datagrams")
    assert proxy.dropped > LOSSY_BYTES // 2000  # the link really lost datagrams each way (1 000 for 2 MB)


@pytest.mark.slow
async def test_mavsdk_round_trips_a_file_through_a_10_percent_loss_link(gcsd_daemon, lossy_proxy, tmp_path):
    daemon = gcsd_daemon()
    root = ftp_root(daemon)
    data = os.urandom(LOSSY_BYTES)
    (root / "two.bin").write_bytes(data)
    proxy = lossy_proxy(daemon.port("gcs"))
    mavsdk, ftp = await _mavsdk_ftp(proxy.port, timeout_s=0.05)
    try:
        started = time.monotonic()
        await asyncio.wait_for(_download(ftp, "/two.bin", tmp_path / "dl"), LOSSY_WAIT_S)
        got_s = time.monotonic() - started
        assert (tmp_path / "dl" / "two.bin").read_bytes() == data
        (root / "sub").mkdir()
        started = time.monotonic()
        await asyncio.wait_for(_upload(ftp, tmp_path / "dl" / "two.bin", "/sub"), 2 * LOSSY_WAIT_S)
        put_s = time.monotonic() - started
        assert (root / "sub" / "two.bin").read_bytes() == data
    finally:
        ftp.destroy()
        mavsdk.destroy()
    print(f"MAVSDK through 10 % loss: download {got_s:.1f} s, upload {put_s:.1f} s; proxy dropped "
          f"{proxy.dropped} of {proxy.dropped + proxy.passed} datagrams")
    assert proxy.dropped > LOSSY_BYTES // 2000  # the link really lost datagrams each way (1 000 for 2 MB)
