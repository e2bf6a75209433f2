"""Flight logs on loopback: download of a 10 MB log by the MAVLink log protocol, and capture of a
DataFlash stream at a 921 600 baud flight controller's rate.

SPEC.md / issue 21: "log download of a 10 MB log on loopback >= 3 MB/s (ArduPilot SITL serves
2.7 MB/s over TCP)"; "capture at 921 600 baud (about 400 blocks/s): no block lost, CPU <= 10 %
of a core".

**Download.** gcsd (`python -m gcsd run`, a simulated copter, one `udp-server` channel, default
settings) with a 10 MB file of random bytes as `state_dir/logs/00000001.BIN`. The client, in the
bench process: one UDP socket with a 4 MiB receive buffer, HEARTBEATs until the vehicle's
arrives, then LOG_REQUEST_LIST (the size from LOG_ENTRY) and LOG_REQUEST_DATA(1, 0, 0xFFFFFFFF)
as MAVProxy asks; LOG_DATA walked by header and unpacked with struct (pymavlink's parser would
be the bottleneck). 0.2 s without a packet: the missing 90-byte chunks are asked for again, as
ranges (at most 20 requests, as MAVProxy). Time: from the LOG_REQUEST_DATA to the last missing
byte; the content is checked (SHA-256). 3 downloads (1 with --quick), the median reported.

**Capture.** gcsd as a companion computer (`vehicle.type: companion`) with `flight_logs.capture:
true` and one `udp-server` channel for the flight controller. The flight controller is the
bench process: it behaves as ArduPilot's AP_Logger_MAVLink (HEARTBEAT at 1 Hz as an ArduPilot
autopilot; streams after a START; 200-byte blocks at BLOCKS_PER_S (400 x 206 payload bytes, with
headers 92 kB/s: a 921 600 baud link's 92 160 bytes/s); every unacknowledged block re-sent after
100 ms; the ACKs and NACKs it gets are walked by header). It runs for CAPTURE_S (10 s with
--quick), then drains. Reported: blocks sent, blocks never acknowledged, whether the captured
file equals the stream byte for byte, and gcsd's CPU (utime + stime from /proc) over the
streaming window as a percentage of one core.

    python -m bench logs           # through bench/run.py (the table at the end)
    python bench/logs.py           # this measurement alone
"""

from __future__ import annotations

import hashlib
import os
import socket
import statistics
import struct
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

if __package__ in (None, ""):  # run as a script: python bench/logs.py
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from bench import report
from bench.frames import received_frames
from bench.routers import Launched, cpu_seconds, free_udp_port, gcsd_config, start_gcsd

TEN_MB = 10_000_000
CHUNK = 90
SPEC_MB_S = 3.0
SITL_MB_S = 2.7
BLOCKS_PER_S = 400
BLOCK = 200
CAPTURE_S = 30.0
SPEC_CPU_PCT = 10.0
QUIET_S = 0.2
MSG_HEARTBEAT, MSG_LOG_ENTRY, MSG_LOG_DATA, MSG_STATUS = 0, 118, 120, 185
START = 2147483646
LOG_DATA = struct.Struct("<IHB")  # ofs, id, count (then data[90])
LOG_ENTRY = struct.Struct("<IIHHH")  # time_utc, size, id, num_logs, last_log_num
STATUS = struct.Struct("<IBBB")  # seqno, target_system, target_component, status


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


@dataclass
class Result:
    download_s: list[float] = field(default_factory=list)
    download_mb_s: float | None = None
    capture_blocks: int = 0
    capture_lost: int = 0
    capture_identical: bool | None = None
    capture_cpu_pct: float | None = None
    capture_rate: float | None = None
    error: str | None = None


class Peer:
    """A raw UDP MAVLink2 endpoint talking to one gcsd channel."""

    def __init__(self, port: int, sysid: int, compid: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.connect(("127.0.0.1", port))
        self.mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=compid)
        self.buf = bytearray(65536)

    def send(self, msg, compid: int | None = None) -> None:
        if compid is not None:
            self.mav.srcComponent = compid
        try:
            self.sock.send(msg.pack(self.mav))
        except ConnectionRefusedError:
            pass

    def frames(self, timeout_s: float):
        """(sysid, msgid, payload bytes padded to 255) of every frame that arrives in one wait."""
        for sysid, msgid, off, plen in received_frames(self.sock, self.buf, timeout_s):
            yield sysid, msgid, bytes(self.buf[off:off + plen]).ljust(255, b"\0")

    def close(self) -> None:
        self.sock.close()


def _wait_heartbeat(peer: Peer, sysid: int, heartbeat, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        peer.send(heartbeat)
        if any(s == sysid and m == MSG_HEARTBEAT for s, m, _ in peer.frames(0.1)):
            return
    raise TimeoutError("no HEARTBEAT from gcsd")


# ------------------------------------------------------------------------------------ download

def download(peer: Peer, size: int, timeout_s: float = 120.0) -> tuple[bytes, float]:
    chunks = (size + CHUNK - 1) // CHUNK
    have = bytearray(chunks)
    out = bytearray(size)
    missing = chunks
    started = time.perf_counter()
    deadline = time.monotonic() + timeout_s
    peer.send(mavlink2.MAVLink_log_request_data_message(1, 1, 1, 0, 0xFFFFFFFF))
    while missing:
        if time.monotonic() > deadline:
            raise TimeoutError(f"log download: {missing} chunks missing")
        got_any = False
        for _sysid, msgid, p in peer.frames(QUIET_S):
            if msgid != MSG_LOG_DATA:
                continue
            ofs, _id, count = LOG_DATA.unpack_from(p)
            got_any = True
            i = ofs // CHUNK
            if count and i < chunks and not have[i]:
                have[i] = 1
                out[ofs:ofs + count] = p[7:7 + count]
                missing -= 1
        if not got_any and missing:  # quiet: ask for the gaps, as MAVProxy
            requests, i = 0, 0
            while i < chunks and requests < 20:
                if have[i]:
                    i += 1
                    continue
                j = i
                while j < chunks and not have[j]:
                    j += 1
                peer.send(mavlink2.MAVLink_log_request_data_message(1, 1, 1, i * CHUNK, (j - i) * CHUNK))
                requests += 1
                i = j
    elapsed = time.perf_counter() - started
    peer.send(mavlink2.MAVLink_log_request_end_message(1, 1))
    return bytes(out), elapsed


def measure_download(workdir: Path, runs: int, env, result: Result) -> None:
    data = os.urandom(TEN_MB)
    logs = workdir / "state" / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    (logs / "00000001.BIN").write_bytes(data)
    digest = hashlib.sha256(data).digest()
    port = free_udp_port()
    profile = os.environ.get("GCSD_BENCH_PROFILE")  # a directory: gcsd runs under cProfile
    gcsd = start_gcsd(workdir, gcsd_config(workdir, [f"{{name: gcs, type: udp-server, address: '127.0.0.1:{port}'}}"]),
                      Path(profile) / "gcsd-logs.prof" if profile else None, env=env)
    peer = Peer(port, 250, 190)
    try:
        hb = mavlink2.MAVLink_heartbeat_message(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
        _wait_heartbeat(peer, 1, hb)
        for n in range(runs):
            got, seconds = download(peer, TEN_MB)
            if hashlib.sha256(got).digest() != digest:
                raise RuntimeError("the downloaded log differs from the file")
            result.download_s.append(seconds)
            log(f"[logs] download {n + 1}/{runs}: {TEN_MB / seconds / 1e6:.2f} MB/s ({seconds:.3f} s)")
            peer.send(hb)
        result.download_mb_s = TEN_MB / statistics.median(result.download_s) / 1e6
    finally:
        peer.close()
        _stop(gcsd)


# ------------------------------------------------------------------------------------- capture

def measure_capture(workdir: Path, seconds: float, env, result: Result) -> None:
    cdir = workdir / "capture"
    cdir.mkdir(exist_ok=True)
    port = free_udp_port()
    cfg = gcsd_config(cdir, [f"{{name: fc, type: udp-server, address: '127.0.0.1:{port}'}}"],
                      "vehicle: {type: companion}\nflight_logs: {capture: true}")
    gcsd = start_gcsd(cdir, cfg, env=env)
    fc = Peer(port, 1, 1)
    stream = bytearray()
    sent_at: dict[int, float] = {}  # unacknowledged seqno -> last sent
    try:
        hb = mavlink2.MAVLink_heartbeat_message(mavlink2.MAV_TYPE_QUADROTOR, mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                0, 0, 3, 3)
        target = None
        deadline = time.monotonic() + 20.0
        while target is None:  # HEARTBEAT until gcsd asks for a START
            if time.monotonic() > deadline:
                raise TimeoutError("gcsd sent no START")
            fc.send(hb, compid=1)
            for sysid, msgid, p in fc.frames(0.2):
                if msgid == MSG_STATUS and STATUS.unpack_from(p)[0] == START:
                    target = (sysid, 191)
        cpu0, t0 = cpu_seconds(gcsd.pid), time.monotonic()
        next_seq, last_hb = 0, t0
        cpu_pct = None
        while True:
            now = time.monotonic()
            if now - t0 >= seconds and cpu_pct is None:
                cpu_pct = 100.0 * (cpu_seconds(gcsd.pid) - cpu0) / (now - t0)
                result.capture_rate = next_seq / (now - t0)
            if now - t0 < seconds:
                due = int((now - t0) * BLOCKS_PER_S) + 1
                while next_seq < due:
                    block = hashlib.sha256(next_seq.to_bytes(4, "little")).digest() * 7
                    block = block[:BLOCK]
                    stream += block
                    sent_at[next_seq] = now
                    fc.send(mavlink2.MAVLink_remote_log_data_block_message(*target, next_seq, block), compid=155)
                    next_seq += 1
            elif not sent_at or now - t0 > seconds + 5.0:
                break
            for seq, last in list(sent_at.items()):
                if now - last >= 0.1:
                    sent_at[seq] = now
                    fc.send(mavlink2.MAVLink_remote_log_data_block_message(
                        *target, seq, bytes(stream[seq * BLOCK:(seq + 1) * BLOCK])), compid=155)
            if now - last_hb >= 1.0:
                last_hb = now
                fc.send(hb, compid=1)
            for _sysid, msgid, p in fc.frames(0.002):
                if msgid == MSG_STATUS:
                    seqno, _ts, _tc, status = STATUS.unpack_from(p)
                    if status == 1:
                        sent_at.pop(seqno, None)
        result.capture_cpu_pct = cpu_pct
        result.capture_blocks = next_seq
        result.capture_lost = len(sent_at)
        time.sleep(6.0)  # the file is finished after CLOSE_AFTER_S of silence
        files = sorted((cdir / "state" / "logs").glob("*.BIN"))
        result.capture_identical = len(files) == 1 and files[0].read_bytes() == bytes(stream)
        log(f"[logs] capture: {next_seq} blocks ({result.capture_rate:.0f}/s), {len(sent_at)} never ACKed, "
            f"file identical: {result.capture_identical}, gcsd CPU {cpu_pct:.1f} % of a core")
    finally:
        fc.close()
        _stop(gcsd)


def _stop(gcsd: Launched) -> None:
    try:
        gcsd.stop()
    except Exception as exc:  # noqa: BLE001  (a bench reports, it does not fail on a slow stop)
        log(f"[logs] stopping gcsd: {exc}")


def measure(workdir: Path, quick: bool, env=None) -> Result:
    result = Result()
    try:
        (workdir / "download").mkdir(parents=True, exist_ok=True)
        measure_download(workdir / "download", 1 if quick else 3, env, result)
        measure_capture(workdir, 10.0 if quick else CAPTURE_S, env, result)
    except Exception as exc:  # noqa: BLE001
        result.error = f"{type(exc).__name__}: {exc}"
        log(f"[logs] failed: {result.error}")
    return result


def table(r: Result) -> str:
    def f(v, spec: str) -> str:
        return "n/a" if v is None else spec.format(v)

    rows = [
        ("log download, 10 MB, loopback UDP, median (MB/s)", f(r.download_mb_s, "{:.2f}"),
         f">= {SPEC_MB_S:g} (SITL {SITL_MB_S:g} over TCP)",
         "" if r.download_mb_s is None else ("yes" if r.download_mb_s >= SPEC_MB_S else "NO")),
        (f"capture at {BLOCKS_PER_S} blocks/s: blocks lost", f(r.capture_lost if r.capture_identical is not None
                                                               else None, "{}"), "0",
         "" if r.capture_identical is None else ("yes" if r.capture_lost == 0 and r.capture_identical else "NO")),
        ("capture: gcsd CPU (% of one core)", f(r.capture_cpu_pct, "{:.1f}"), f"<= {SPEC_CPU_PCT:g}",
         "" if r.capture_cpu_pct is None else ("yes" if r.capture_cpu_pct <= SPEC_CPU_PCT else "NO")),
    ]
    head = ("metric", "gcsd", "target", "meets")
    widths = [max(len(x[i]) for x in (head, *rows)) for i in range(4)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(x, widths)) for x in (head, *rows)]
    lines.insert(1, "  ".join("-" * w for w in widths))
    notes = [f"downloads: {', '.join(f'{s:.3f}' for s in r.download_s)} s",
             f"capture: {r.capture_blocks} blocks sent, file byte-identical: {r.capture_identical}"]
    if r.error:
        notes.append(f"error: {r.error}")
    return "\n".join([*lines, "", *notes])


def main(argv: list[str]) -> int:
    return report.standalone(argv, "logs", __doc__, "one download, 10 s of capture", measure, table,
                             lambda r: r.error is not None)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
