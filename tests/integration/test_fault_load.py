"""Fault and load suite (issue 8): the real daemon as a process, abused on every channel.

- Noise: random bytes and random frames with valid CRCs, random fields and random targets, on a
  UDP, a TCP and a serial (PTY) channel for FAULT_SECONDS (default 60), while a ground station
  on a clean channel checks its telemetry rate, and peak memory is sampled. Frames a ground
  station would use to change stored state on purpose (PARAM_SET, mission uploads and clears,
  SETUP_SIGNING, FTP, commands) are left out of the random mix: those are authenticated
  operations (signing), not faults. Afterwards the parameters and the mission are unchanged.
- Ten ground stations download all parameters and the mission at the same time.
- The serial device is unplugged (PTY closed) and comes back: the channel reconnects.

(A ground station vanishing mid-upload, the 8 s abort with the plan in force kept and another
station downloading it at once, is pinned with a float clock in tests/unit/test_mission_transfer.py.)

Figures (frames thrown, drops by reason, peak RSS) are printed and written to
$GCSD_FAULT_REPORT when set, for bench/RESULTS.md.
"""

from __future__ import annotations

import json
import os
import random
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from pymavlink.generator.mavcrc import x25crc

from .helpers import Client, M, await_ready, download_params, notify_socket, pump, stamped_rate_hz

pytestmark = pytest.mark.fault

FAULT_SECONDS = float(os.environ.get("GCSD_FAULT_SECONDS", "60"))
VEHICLE = (1, 1)
STATE_CHANGING = {
    M.MAVLINK_MSG_ID_PARAM_SET, M.MAVLINK_MSG_ID_MISSION_COUNT, M.MAVLINK_MSG_ID_MISSION_CLEAR_ALL,
    M.MAVLINK_MSG_ID_MISSION_WRITE_PARTIAL_LIST, M.MAVLINK_MSG_ID_MISSION_ITEM, M.MAVLINK_MSG_ID_MISSION_ITEM_INT,
    M.MAVLINK_MSG_ID_SETUP_SIGNING, M.MAVLINK_MSG_ID_FILE_TRANSFER_PROTOCOL, M.MAVLINK_MSG_ID_COMMAND_LONG,
    M.MAVLINK_MSG_ID_COMMAND_INT, M.MAVLINK_MSG_ID_PARAM_EXT_SET, M.MAVLINK_MSG_ID_SET_MODE,
    M.MAVLINK_MSG_ID_MISSION_SET_CURRENT, M.MAVLINK_MSG_ID_FENCE_POINT, M.MAVLINK_MSG_ID_RALLY_POINT,
    M.MAVLINK_MSG_ID_SERIAL_CONTROL, M.MAVLINK_MSG_ID_SET_POSITION_TARGET_GLOBAL_INT,
    M.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED, M.MAVLINK_MSG_ID_RC_CHANNELS_OVERRIDE,
    M.MAVLINK_MSG_ID_MANUAL_CONTROL, M.MAVLINK_MSG_ID_SET_HOME_POSITION, M.MAVLINK_MSG_ID_PARAM_MAP_RC,
}
RANDOM_IDS = sorted(set(M.mavlink_map) - STATE_CHANGING)


def free_port(kind=socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def random_frame(rng: random.Random) -> bytes:
    """A MAVLink2 frame with a valid CRC: a known id, random payload (so random targets) and source."""
    msgid = rng.choice(RANDOM_IDS)
    cls = M.mavlink_map[msgid]
    payload = rng.randbytes(rng.randint(1, cls.unpacker.size))
    header = bytes([0xFD, len(payload), 0, 0, rng.randrange(256), rng.randint(1, 255), rng.randint(0, 255),
                    msgid & 0xFF, (msgid >> 8) & 0xFF, msgid >> 16])
    crc = x25crc(header[1:] + payload)
    crc.accumulate(bytes([cls.crc_extra]))
    return header + payload + struct.pack("<H", crc.crc)


def noise(rng: random.Random) -> bytes:
    return random_frame(rng) if rng.random() < 0.6 else rng.randbytes(rng.randint(1, 300))


class Daemon:
    """gcsd as a process with known ports; RSS from /proc."""

    def __init__(self, tmp: Path, channels: list[dict]) -> None:
        self.state = tmp / "state"
        self.config = tmp / "gcsd.yaml"
        import yaml

        self.config.write_text(yaml.safe_dump({
            "state_dir": str(self.state), "log": {"level": "warning", "format": "json"}, "channels": channels,
        }))
        notify, notify_path = notify_socket(tmp)
        self.proc = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(self.config)],
                                     env={**os.environ, "NOTIFY_SOCKET": str(notify_path)},
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        with notify:
            await_ready(notify, self.proc)  # every channel bound (a first request sent earlier is lost)

    def rss_kb(self) -> int:
        for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
        return 0

    def status(self) -> dict:
        from gcsd.api.control import query

        return query(self.state / "gcsd.sock")

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                return self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
                return -9
        return self.proc.returncode


def param_names(c: Client, timeout: float = 20.0, others=()) -> dict[int, tuple[str, float]]:
    return {i: (name, value) for i, (name, value, _type) in download_params(c, timeout, others).items()}


def mission_items(n: int) -> list:
    return [
        M.MAVLink_mission_item_int_message(*VEHICLE, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_CMD_NAV_WAYPOINT,
                                           0, 1, 0, 0, 0, 0, int(-35.36e7) + seq * 1000, int(149.16e7), 20.0 + seq)
        for seq in range(n)
    ]


def upload_mission(c: Client, items: list, stop_after: int | None = None, timeout: float = 15.0) -> int | None:
    """Upload; answer requests until done (or go silent after `stop_after` items); returns the ACK result."""
    mark = c.mark()
    c.send(M.MAVLink_mission_count_message(*VEHICLE, len(items), 0))
    answered = 0
    deadline = time.monotonic() + timeout
    seen = mark
    while time.monotonic() < deadline:
        pump([c], 0.05)
        for r in c.received[seen:]:
            if r.src != VEHICLE:
                continue
            if r.type in ("MISSION_REQUEST", "MISSION_REQUEST_INT") and r.msg.mission_type == 0:
                if stop_after is not None and answered >= stop_after:
                    return None
                c.send(items[r.msg.seq])
                answered += 1
            elif r.type == "MISSION_ACK" and r.msg.mission_type == 0:
                return r.msg.type
        seen = len(c.received)
    raise AssertionError("mission upload timed out")


def download_mission(c: Client, timeout: float = 15.0, others=()) -> list[tuple] | int:
    """Download; returns (seq, command, x, y, z) tuples, or the MISSION_ACK error that refused it."""
    mark = c.mark()
    c.send(M.MAVLink_mission_request_list_message(*VEHICLE, 0))
    count = None
    got: dict[int, tuple] = {}
    deadline = time.monotonic() + timeout
    last_request = 0.0
    seen = mark
    while time.monotonic() < deadline:
        pump([c, *others], 0.05)
        for r in c.received[seen:]:
            if r.src != VEHICLE:
                continue
            if r.type == "MISSION_COUNT" and r.msg.mission_type == 0 and count is None:
                count = r.msg.count
            elif r.type == "MISSION_ITEM_INT" and r.msg.mission_type == 0:
                got[r.msg.seq] = (r.msg.seq, r.msg.command, r.msg.x, r.msg.y, round(r.msg.z, 3))
            elif r.type == "MISSION_ACK" and r.msg.mission_type == 0 and count is None:
                return r.msg.type
        seen = len(c.received)
        if count is not None:
            missing = [i for i in range(count) if i not in got]
            if not missing:
                c.send(M.MAVLink_mission_ack_message(*VEHICLE, 0, 0))
                return [got[i] for i in range(count)]
            if time.monotonic() - last_request > 0.3:
                for seq in missing[:5]:
                    c.send(M.MAVLink_mission_request_int_message(*VEHICLE, seq, 0))
                last_request = time.monotonic()
    raise AssertionError("mission download timed out")


def test_noise_and_random_frames_on_every_channel_leave_the_daemon_serving(tmp_path):
    master, slave = os.openpty()
    os.set_blocking(master, False)
    ports = {"clean": free_port(), "udp": free_port(), "tcp": free_port(socket.SOCK_STREAM)}
    d = Daemon(tmp_path, [
        {"name": "clean", "type": "udp-server", "address": f"127.0.0.1:{ports['clean']}", "streams": {"extra1": 5}},
        {"name": "noisy_udp", "type": "udp-server", "address": f"127.0.0.1:{ports['udp']}"},
        {"name": "noisy_tcp", "type": "tcp-server", "address": f"127.0.0.1:{ports['tcp']}"},
        {"name": "noisy_serial", "type": "serial", "device": os.ttyname(slave), "baud": 921600},
    ])
    gcs = Client(f"udpout:127.0.0.1:{ports['clean']}", 255, 190)
    thrown = {"frames": 0, "bytes": 0}
    stop = threading.Event()
    try:
        gcs.heartbeat()
        params_before = param_names(gcs)
        assert upload_mission(gcs, mission_items(12)) == M.MAV_MISSION_ACCEPTED
        mission_before = download_mission(gcs)

        def thrower(seed: int) -> None:
            rng = random.Random(seed)
            udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            tcp = socket.create_connection(("127.0.0.1", ports["tcp"]))
            try:
                while not stop.is_set():
                    for _ in range(20):
                        blob = noise(rng)
                        udp.sendto(blob, ("127.0.0.1", ports["udp"]))
                        tcp.sendall(noise(rng))
                        try:
                            os.write(master, noise(rng))
                        except (BlockingIOError, OSError):
                            pass
                        thrown["frames"] += 3
                        thrown["bytes"] += len(blob) * 3
                    time.sleep(0.02)  # about 3 000 frames per second over the three channels
                    try:
                        while os.read(master, 65536):
                            pass
                    except (BlockingIOError, OSError):
                        pass
            finally:
                udp.close()
                tcp.close()

        worker = threading.Thread(target=thrower, args=(20261122,), daemon=True)
        worker.start()
        rss = []
        rates = []
        end = time.monotonic() + FAULT_SECONDS
        while time.monotonic() < end:
            mark = gcs.mark()
            gcs.heartbeat()
            pump([gcs], 2.0)
            # on the daemon's clock (ATTITUDE's stamps): the reader's own scheduling is not measured
            rates.append(stamped_rate_hz([r for r in gcs.since(mark, "ATTITUDE") if r.src == VEHICLE]))
            rss.append(d.rss_kb())
            assert d.proc.poll() is None, "gcsd died under noise"
        stop.set()
        worker.join(5)
        status = d.status()
        report = {
            "seconds": FAULT_SECONDS, "frames_thrown": thrown["frames"], "peak_rss_kb": max(rss),
            "rss_first_kb": rss[0], "rss_last_kb": rss[-1], "clean_channel_attitude_hz_min": min(rates),
            "clean_channel_attitude_hz_median": sorted(rates)[len(rates) // 2],
            "channels": {c["name"]: {k: c[k] for k in ("packets_in", "parse_errors", "crc_errors", "unknown_ids",
                                                      "seq_gaps", "drops", "signature_rejects")}
                         for c in status["channels"]},
        }
        print(json.dumps(report, indent=2))
        if os.environ.get("GCSD_FAULT_REPORT"):
            Path(os.environ["GCSD_FAULT_REPORT"]).write_text(json.dumps(report, indent=2))
        assert min(rates) == pytest.approx(5.0, rel=0.15), rates
        assert max(rss) < 120_000, "resident memory stays bounded"
        assert rss[-1] - rss[len(rss) // 2] < 8_000, "no growth in the second half"
        noisy = [report["channels"][n] for n in ("noisy_udp", "noisy_tcp", "noisy_serial")]
        assert all(c["parse_errors"] + c["crc_errors"] > 0 for c in noisy)
        assert param_names(gcs) == params_before
        assert download_mission(gcs) == mission_before
    finally:
        stop.set()
        gcs.close()
        assert d.stop() == 0
        os.close(master)
        os.close(slave)


def test_ten_ground_stations_download_parameters_and_the_mission_at_once(tmp_path):
    """Ten stations served at once on one channel: max_peers (8 by default) is set to ten, as an
    operator with ten would. At the default, each newcomer replaced the station silent the
    longest (4 replacements in a passing run), and a station replaced before its first
    PARAM_VALUE, silent until then, heard nothing more: 'parameter download incomplete: 0 of None'
    under load. Replacing a peer is tested in test_hardening.py and tests/unit/test_unauth.py."""
    port = free_port()
    d = Daemon(tmp_path, [{"name": "gcs", "type": "udp-server", "address": f"127.0.0.1:{port}", "max_peers": 10}])
    clients = [Client(f"udpout:127.0.0.1:{port}", 200 + i, 190) for i in range(10)]
    try:
        assert upload_mission(clients[0], mission_items(30)) == M.MAV_MISSION_ACCEPTED
        results: dict[int, tuple] = {}
        errors: list[BaseException] = []

        def hammer(i: int) -> None:
            try:
                c = clients[i]
                results[i] = (len(param_names(c)), len(download_mission(c)))
            except Exception as exc:  # noqa: BLE001  (surfaced below, in the test thread)
                errors.append(exc)

        threads = [threading.Thread(target=hammer, args=(i,)) for i in range(10)]
        start = time.monotonic()
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
        elapsed = time.monotonic() - start
        gcs = next(c for c in d.status()["channels"] if c["name"] == "gcs")
        assert (gcs["peers"], gcs["peers_replaced"]) == (10, 0), "all ten served at once, none replaced"
        assert not errors, errors
        assert len({v for v in results.values()}) == 1 and len(results) == 10, results
        assert results[0][1] == 30  # item 0 of an upload is home
        print(f"10 ground stations: parameters and mission in {elapsed:.2f} s")
        assert d.proc.poll() is None
    finally:
        for c in clients:
            c.close()
        assert d.stop() == 0


def test_serial_device_unplugged_and_back_reconnects(tmp_path):
    link = tmp_path / "ttyFC"
    master, slave = os.openpty()
    link.symlink_to(os.ttyname(slave))
    d = Daemon(tmp_path, [{"name": "fc", "type": "serial", "device": str(link), "baud": 115200}])
    parser = M.MAVLink(None)
    parser.robust_parsing = True

    def heartbeats_from(fd: int, seconds: float, wanted: int = 2) -> int:
        """HEARTBEATs read from fd until `wanted` have come or `seconds` have passed."""
        n = 0
        end = time.monotonic() + seconds
        os.set_blocking(fd, False)
        while time.monotonic() < end and n < wanted:
            try:
                data = os.read(fd, 4096)
            except (BlockingIOError, OSError):
                time.sleep(0.05)
                continue
            n += sum(1 for m in parser.parse_buffer(data) or [] if m.get_type() == "HEARTBEAT")
        return n

    try:
        os.write(master, M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(M.MAVLink(None, 255, 190)))
        assert heartbeats_from(master, 9.0) >= 2, "the serial channel is served"  # 1 Hz, however loaded
        # unplugged: the by-id link goes with the device, as udev removes it. Left pointing at the
        # freed /dev/pts/N, it let the daemon's reopening take the next PTY given that number, another
        # test's (a parallel worker's): it flushed and read that test's input (test_serial_control's
        # device answer vanished, 1 run in 3 of four files at once beside CPU hogs)
        link.unlink()
        os.close(master)
        os.close(slave)
        time.sleep(1.5)
        assert d.proc.poll() is None
        master, slave = os.openpty()  # plugged back in, maybe under another name
        link.symlink_to(os.ttyname(slave))
        os.write(master, M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(M.MAVLink(None, 255, 190)))
        assert heartbeats_from(master, 9.0) >= 2, "the serial channel came back"
    finally:
        assert d.stop() == 0
        for fd in (master, slave):
            try:
                os.close(fd)
            except OSError:
                pass
