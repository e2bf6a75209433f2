"""MAVLink FTP on loopback: burst read of a 10 MB file, and `@PARAM/param.pck` of 1 000
parameters, gcsd against MAVSDK's ftp_server serving the same bytes.

SPEC.md: "FTP burst read of a 10 MB file >= 3 MB/s"; "`@PARAM/param.pck` of 1 000 parameters
over FTP <= 0.1 s".

Servers (each its own process, sysid 1 / compid 1, one UDP port on 127.0.0.1):

- ``gcsd (1 000 params)``: bench/params.py's ``serve-gcsd`` (gcsd's own CLI with the vehicle's
  parameter definitions padded to 1 000, a bench-only vehicle setup; the FTP code is unchanged),
  one ``udp-server`` channel, default stream rates. Its FTP root (``<state_dir>/ftp``) holds the
  10 MB file (random bytes).
- ``MAVSDK ftp_server``: the ``mavsdk`` package (C++ core through ctypes) as an AUTOPILOT on
  ``udpin://127.0.0.1:PORT``, ``FtpServer.set_root_dir`` on a directory holding the same 10 MB
  file and ``param.pck``: the exact bytes gcsd served (MAVSDK has no ``@PARAM``; the same bytes
  make the same transfer).

Client (the same for both, in the bench process): one UDP socket with a 4 MiB receive buffer;
requests packed with pymavlink, replies walked by header (the payload header read with struct),
so the client is not the bottleneck. It sends HEARTBEATs until the server's arrives. One
download: OpenFileRO (re-sent every 0.2 s until answered), BurstReadFile with block 239 from
offset 0; on burst_complete or the EOF NAK a new burst from the end of what arrived, until the
size given at open is covered; chunks lost in a burst are read afterwards with ReadFile, 8 in
flight; 0.2 s without a packet re-sends what is outstanding; TerminateSession. Time: from just
before the OpenFileRO send to the arrival of the last missing byte. The content is checked after
each download (SHA-256 for the 10 MB file; MAVProxy's param_ftp decoder for param.pck: 1 000
parameters). gcsd: 5 downloads of 10 MB, 20 of param.pck (2 and 5 with --quick); MAVSDK: one of
10 MB (it takes about 90 s: its server sends a burst at about 0.1 MB/s), 20 (5) of param.pck.
The median is reported; throughput = size / median time.

gcsd serves ArduCopter 4.6's own set here: 1 000 parameters with one channel
(params/data/copter.tsv), so serve-gcsd's padding adds nothing.

    python -m bench ftp            # through bench/run.py (the table at the end)
    python bench/ftp.py            # this measurement alone, with its own table
"""

from __future__ import annotations

import hashlib
import os
import select
import socket
import statistics
import struct
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

if __package__ in (None, ""):  # run as a script: python bench/ftp.py
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from bench import mavsdk_peer, report
from bench.frames import received_frames, walk_frames
from bench.routers import Launched, _launch, free_udp_port, gcsd_config

THIS = Path(__file__).resolve()
REPO = THIS.parent.parent
TOTAL = 1000
TEN_MB = 10_000_000
BLOCK = 239
SPEC_MB_S = 3.0
SPEC_PCK_S = 0.1
VEHICLE = (1, 1)
CLIENT = (250, 190)
MSGID_HEARTBEAT, MSGID_FTP = 0, 110
OP_TERMINATE, OP_OPEN_RO, OP_READ, OP_BURST, ACK, NAK = 1, 4, 5, 15, 128, 129
HDR = struct.Struct("<HBBBBBxI")
IN_FLIGHT = 8
QUIET_S = 0.2


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------------ servers

def serve_mavsdk(port: int, root: str) -> int:
    """MAVSDK's ftp_server as an autopilot on udpin://127.0.0.1:port, until SIGTERM."""
    from mavsdk.plugins.ftp_server import FtpServer

    with mavsdk_peer.node(f"udpin://127.0.0.1:{port}", autopilot=True) as mavsdk:
        server = FtpServer(mavsdk.server_component())
        server.set_root_dir(root)
        return mavsdk_peer.serve_until_sigterm(server)


def _wait_ready(server: Launched, marker: str | None, port: int, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if not server.alive():
            raise RuntimeError(f"{server.name} exited: {server.tail()}")
        if marker is None or marker in server.log_path.read_text(errors="replace"):
            return
        time.sleep(0.1)
    raise RuntimeError(f"{server.name} not ready within {timeout_s} s: {server.tail()}")


# ------------------------------------------------------------------------------------- client

@dataclass
class Download:
    seconds: float
    size: int
    packets: int
    gap_reads: int
    duplicates: int


class FtpClient:
    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.connect(("127.0.0.1", port))
        self.mav = mavlink2.MAVLink(None, srcSystem=CLIENT[0], srcComponent=CLIENT[1])
        self.buf = bytearray(65536)
        self.seq = 0
        self.session = 7

    def close(self) -> None:
        self.sock.close()

    def _send(self, msg) -> None:
        try:
            self.sock.send(msg.pack(self.mav))
        except ConnectionRefusedError:
            pass

    def request(self, opcode: int, size: int = 0, offset: int = 0, data: bytes = b"") -> None:
        payload = HDR.pack(self.seq, self.session, opcode, size, 0, 0, offset) + data
        self.seq = (self.seq + 1) & 0xFFFF
        payload += bytes(251 - len(payload))
        self._send(mavlink2.MAVLink_file_transfer_protocol_message(0, *VEHICLE, payload))

    def replies(self, timeout_s: float):
        """FTP payload headers (and data) from the vehicle in the datagrams of one wait."""
        for sysid, msgid, off, plen in received_frames(self.sock, self.buf, timeout_s):
            if msgid == MSGID_FTP and sysid == VEHICLE[0]:  # MAVLink2: we speak it, so the server does
                body = bytes(self.buf[off + 3:off + plen]).ljust(251, b"\0")
                yield HDR.unpack_from(body), body[12:]

    def connect(self, timeout_s: float = 20.0) -> None:
        hb = mavlink2.MAVLink_heartbeat_message(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID,
                                                0, 0, 0, 3)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self._send(hb)
            if select.select([self.sock], [], [], 0.1)[0]:
                try:
                    n = self.sock.recv_into(self.buf)
                except ConnectionRefusedError:
                    continue
                if any(s == VEHICLE[0] and m == MSGID_HEARTBEAT for s, m, _ in walk_frames(self.buf, n)):
                    return
        raise TimeoutError(f"no HEARTBEAT from the server within {timeout_s} s")

    def download(self, path: str, timeout_s: float = 120.0) -> tuple[bytes, Download]:
        self.session = (self.session % 200) + 1
        name = path.encode()
        started = time.perf_counter()
        deadline = time.monotonic() + timeout_s
        size = None
        sent_s = 0.0
        while size is None:
            now = time.monotonic()
            if now > deadline:
                raise TimeoutError(f"OpenFileRO {path}: no answer")
            if now - sent_s >= QUIET_S:  # a retry is the same request, byte for byte
                if sent_s:
                    self.seq = (self.seq - 1) & 0xFFFF
                self.request(OP_OPEN_RO, len(name), 0, name)
                sent_s = now
            for (seq, session, op, sz, req, bc, offset), data in self.replies(QUIET_S):
                if req == OP_OPEN_RO and op == ACK:
                    size, self.session = struct.unpack_from("<I", data)[0], session
                    break
                if req == OP_OPEN_RO and op == NAK:
                    raise RuntimeError(f"OpenFileRO {path}: NAK {data[0]}")
        chunks = (size + BLOCK - 1) // BLOCK
        have = bytearray(chunks)
        missing = chunks
        out = bytearray(size)
        top = 0  # one past the highest chunk received
        packets = gap_reads = duplicates = 0
        asked: dict[int, float] = {}
        self.request(OP_BURST, BLOCK, 0)
        burst_open = True
        last_s = time.monotonic()  # when the last FTP packet came (or the burst was asked for)
        while missing:
            if time.monotonic() > deadline:
                raise TimeoutError(f"{path}: {missing} of {chunks} chunks missing")
            for (seq, session, op, sz, req, bc, offset), data in self.replies(QUIET_S):
                if req not in (OP_BURST, OP_READ):
                    continue
                last_s = time.monotonic()
                if op == ACK:
                    packets += 1
                    i = offset // BLOCK
                    if i < chunks and not have[i]:
                        have[i] = 1
                        missing -= 1
                        out[offset:offset + sz] = data[:sz]
                        asked.pop(i, None)
                    else:
                        duplicates += 1
                    top = max(top, i + 1)
                if req == OP_BURST and (bc or op == NAK):
                    burst_open = False
            now = time.monotonic()
            quiet = now - last_s >= QUIET_S
            if not burst_open and top < chunks:
                self.request(OP_BURST, BLOCK, top * BLOCK)
                burst_open, last_s = True, now
            if not burst_open or quiet:
                for i in (j for j in range(top) if not have[j]):
                    if len([t for t in asked.values() if now - t < QUIET_S]) >= IN_FLIGHT:
                        break
                    if now - asked.get(i, 0.0) >= QUIET_S:
                        self.request(OP_READ, BLOCK, i * BLOCK)
                        asked[i] = now
                        gap_reads += 1
            if quiet and burst_open:
                self.request(OP_BURST, BLOCK, top * BLOCK)  # the burst went quiet: go on from the top
                last_s = now
        seconds = time.perf_counter() - started
        self.request(OP_TERMINATE)
        list(self.replies(0.05))
        return bytes(out), Download(seconds, size, packets, gap_reads, duplicates)


# --------------------------------------------------------------------------------- measurement

@dataclass
class Result:
    name: str
    big: list[Download] = field(default_factory=list)
    pck: list[Download] = field(default_factory=list)
    params: int = 0
    error: str | None = None
    stop: str = ""

    @staticmethod
    def _median(ds: list[Download]) -> float | None:
        return statistics.median(d.seconds for d in ds) if ds else None

    @property
    def big_mb_s(self) -> float | None:
        m = self._median(self.big)
        return None if m is None else TEN_MB / m / 1e6

    @property
    def pck_s(self) -> float | None:
        return self._median(self.pck)


def _decode_pck(data: bytes) -> int:
    from MAVProxy.modules.lib import param_ftp

    decoded = param_ftp.ftp_param_decode(data)
    if decoded is None:
        raise RuntimeError("param.pck did not decode")
    return len(decoded.params)


def _run(result: Result, server: Launched, marker: str | None, port: int, big_reps: int, pck_reps: int,
         big_sha: str, pck_path: str, expect_pck: bytes | None) -> bytes | None:
    client = None
    got_pck = None
    try:
        _wait_ready(server, marker, port)
        client = FtpClient(port)
        client.connect()
        for _ in range(big_reps):
            data, d = client.download("big.bin")
            if hashlib.sha256(data).hexdigest() != big_sha:
                raise RuntimeError("the 10 MB file arrived corrupted")
            result.big.append(d)
            log(f"[ftp] {result.name}: 10 MB in {d.seconds:.3f} s ({TEN_MB / d.seconds / 1e6:.2f} MB/s), "
                f"{d.gap_reads} gap reads, {d.duplicates} duplicates")
        for _ in range(pck_reps):
            data, d = client.download(pck_path)
            if expect_pck is not None and data != expect_pck:
                raise RuntimeError("param.pck differs from gcsd's")
            result.params = _decode_pck(data)
            result.pck.append(d)
            got_pck = data
        if result.pck:
            log(f"[ftp] {result.name}: param.pck ({result.pck[0].size} bytes, {result.params} params) "
                f"median {statistics.median(d.seconds for d in result.pck) * 1000:.1f} ms")
    except (RuntimeError, TimeoutError, OSError) as exc:
        result.error = str(exc)
        log(f"[ftp] {result.name} FAILED: {exc}")
    finally:
        if client is not None:
            client.close()
        result.stop = server.stop()
    return got_pck


def measure(workdir: Path, quick: bool = False, env: dict | None = None) -> dict[str, Result]:
    big_reps, pck_reps = (2, 5) if quick else (5, 20)
    env = dict(os.environ if env is None else env)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    big = os.urandom(TEN_MB)
    big_sha = hashlib.sha256(big).hexdigest()
    results = {"gcsd": Result(f"gcsd ({TOTAL} params)"), "mavsdk": Result("MAVSDK ftp_server")}

    port = free_udp_port()
    cfg = gcsd_config(workdir, [f'{{name: gcs, type: udp-server, address: "127.0.0.1:{port}"}}'])
    (workdir / "state" / "ftp").mkdir(parents=True, exist_ok=True)
    (workdir / "state" / "ftp" / "big.bin").write_bytes(big)
    log(f"[ftp] gcsd padded to {TOTAL} parameters: {big_reps} x 10 MB, {pck_reps} x @PARAM/param.pck")
    server = _launch("gcsd-ftp", [sys.executable, str(REPO / "bench" / "params.py"), "serve-gcsd", str(cfg),
                                  str(TOTAL)], workdir, env)
    pck = _run(results["gcsd"], server, None, port, big_reps, pck_reps, big_sha, "@PARAM/param.pck", None)

    root = workdir / "mavsdk-root"
    root.mkdir(exist_ok=True)
    (root / "big.bin").write_bytes(big)
    if pck is not None:
        (root / "param.pck").write_bytes(pck)
    port = free_udp_port()
    log(f"[ftp] MAVSDK ftp_server: 1 x 10 MB, {pck_reps if pck else 0} x the same param.pck bytes")
    server = _launch("mavsdk-ftp-server", [sys.executable, str(THIS), "serve-mavsdk", str(port), str(root)],
                     workdir, env)
    _run(results["mavsdk"], server, "ready", port, 1, pck_reps if pck else 0, big_sha, "/param.pck", pck)
    return results


# ------------------------------------------------------------------------------------- table

def rows(results: dict[str, Result]):
    g, m = results.get("gcsd"), results.get("mavsdk")

    def get(r, attr, scale=1.0):
        v = None if r is None else getattr(r, attr)
        return None if v is None else v * scale

    return [
        ("FTP burst read, 10 MB file, median (MB/s)", get(g, "big_mb_s"), get(m, "big_mb_s"), "hi",
         f">= {SPEC_MB_S:g}", lambda v: v >= SPEC_MB_S),
        (f"@PARAM/param.pck, {TOTAL} params, median (ms)", get(g, "pck_s", 1000), get(m, "pck_s", 1000), "lo",
         f"<= {SPEC_PCK_S * 1000:g}", lambda v: v <= SPEC_PCK_S * 1000),
    ]


def notes(results: dict[str, Result]) -> list[str]:
    out = []
    for r in results.values():
        if r.error:
            out.append(f"{r.name}: {r.error}")
        parts = []
        if r.big:
            parts.append("10 MB: " + ", ".join(f"{d.seconds:.3f}" for d in r.big) + " s, gap reads "
                         + ", ".join(str(d.gap_reads) for d in r.big))
        if r.pck:
            parts.append(f"param.pck ({r.pck[0].size} bytes, {r.params} params): "
                         + ", ".join(f"{d.seconds * 1000:.1f}" for d in r.pck) + " ms")
        if parts:
            out.append(f"{r.name}: " + "; ".join(parts) + f"; {r.stop}")
    return out


def table(results: dict[str, Result]) -> str:
    return report.comparison_table("MAVSDK ftp_server", rows(results), notes(results))


def main(argv: list[str]) -> int:
    if argv and argv[0] == "serve-mavsdk":
        return serve_mavsdk(int(argv[1]), argv[2])
    return report.standalone(argv, "ftp", __doc__, "2 x 10 MB and 5 x param.pck per server", measure, table,
                             lambda results: any(r.error for r in results.values()))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
