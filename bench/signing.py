"""Routing throughput with MAVLink2 signing on both channels, beside the unsigned figure.

gcsd routes between two ``udp-server`` channels ``a`` and ``b`` exactly as in the ``throughput``
measurement (bench/README.md), once as there (no signing) and once with
``signing: {key: KEY, require: true}``: every packet in either direction must then carry a valid
signature, and gcsd checks each one (SHA-256 over the frame, per-stream timestamp) before it
learns, forwards or handles it. The sender, the receiver, the trial and the search are those of
``measure.search_throughput``; the figure is packets/s routed without loss, and the ratio
signed / unsigned.

Signed traffic. The sender's COMMAND_LONG frames are made as for the unsigned run
(``frames.FrameFactory``) and then signed, all of them up front in ``prepare`` (untimed), so the
sender stays as fast as the unsigned one: the incompat flag ``MAVLINK_IFLAG_SIGNED`` is set (the
CRC covers it; for frames of one length the CRC changes by a constant, taken from pymavlink's
own signed and unsigned encodings of the template), then link id, a 48-bit timestamp and the
first 6 bytes of SHA-256(key + frame + link id + timestamp) are appended: 57 bytes instead of 44.
The timestamps are distinct and increasing (the wall clock in 10 us units at ``prepare``, + 1 per
frame, never below the last one used), so no frame looks like a replay. ``check()`` proves the
frames are byte-identical to pymavlink's signed encoding of the same message with the same link
id and timestamp, and that pymavlink, holding the key, accepts their signatures. HEARTBEATs of
sender and receiver are signed by pymavlink itself (``MAVLink.signing``), on link id 1 for the
sender so that they form a stream of their own: gcsd requires strictly increasing timestamps
per (sysid, compid, link id), and a heartbeat signed while pre-signed frames are in flight would
otherwise break that order.

The signing peers are ``peers.sender_main`` and ``peers.receiver_main`` themselves, run in their
own processes after replacing ``peers.FrameFactory`` and ``peers.heartbeat`` in that process, so
pacing, counting and reporting are the same code as for the unsigned run.

After the signed search, a check that signing is enforced: 1 s of the unsigned sender's frames
(1 000/s) to the signed gcsd must deliver nothing, and ``gcsd status --json`` must count them as
``unsigned`` rejects; the signature rejects of channels ``a`` and ``b`` are recorded (anything
but those probe packets would mean the measurement itself was refused).

    python -m bench signing            # through bench/run.py (its table at the end)
    python -m bench signing --quick
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import time

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from bench import measure
from bench.frames import SENDER_COMPID, SENDER_SYSID, TARGET_COMPID, TARGET_SYSID, FrameFactory
from bench.measure import Path, log
from bench.peers import Peer
from bench.routers import STREAMS_OFF, free_udp_port, gcsd_config, start_gcsd

KEY = hashlib.sha256(b"gcsd bench signing").digest()
DATA_LINK_ID = 0
HEARTBEAT_LINK_ID = 1
EPOCH_2015_S = 1420070400
UNITS_PER_S = 100_000  # signing timestamps count 10 us
PROBE_RATE = 1000
PROBE_S = 1.0


def wall_units() -> int:
    return int((time.time() - EPOCH_2015_S) * UNITS_PER_S)


def _signed_mav(key: bytes, sysid: int, compid: int, link_id: int) -> mavlink2.MAVLink:
    mav = mavlink2.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.signing.secret_key = key
    mav.signing.link_id = link_id
    mav.signing.sign_outgoing = True
    mav.signing.timestamp = 0
    return mav


class SignedFrameFactory:
    """``FrameFactory``'s frames, signed; see the module docstring."""

    def __init__(self, key: bytes = KEY, link_id: int = DATA_LINK_ID) -> None:
        self.key = bytes(key)
        self.link_id = link_id
        self._plain = FrameFactory()
        self.length = self._plain.length + 13
        self.timestamp = 0  # the last one used
        # CRC change for MAVLINK_IFLAG_SIGNED, from pymavlink's signed and unsigned template frames
        plain = self._plain.frame(0)
        signed = self._pymavlink_frame(0, 1)
        assert signed[0] == 0xFD and signed[2] == 0x01 and len(signed) == self.length
        self._crc_delta = int.from_bytes(signed[-15:-13], "little") ^ int.from_bytes(plain[-2:], "little")

    def _pymavlink_frame(self, seq: int, timestamp: int) -> bytes:
        mav = _signed_mav(self.key, SENDER_SYSID, SENDER_COMPID, self.link_id)
        mav.seq = seq & 0xFF
        mav.signing.timestamp = timestamp
        msg = mav.command_long_encode(TARGET_SYSID, TARGET_COMPID, mavlink2.MAV_CMD_USER_1, 0, float(seq),
                                      0, 0, 0, 0, 0, 0)
        return bytes(msg.pack(mav))

    def frame(self, seq: int, timestamp: int) -> bytes:
        b = bytearray(self._plain.frame(seq))
        b[2] = 0x01  # incompat_flags: MAVLINK_IFLAG_SIGNED
        crc = (b[-2] | (b[-1] << 8)) ^ self._crc_delta
        b[-2] = crc & 0xFF
        b[-1] = crc >> 8
        b.append(self.link_id)
        b += timestamp.to_bytes(6, "little")
        b += hashlib.sha256(self.key + b).digest()[:6]
        return bytes(b)

    def frames(self, start: int, count: int) -> list[bytes]:
        ts = max(self.timestamp + 1, wall_units())
        self.timestamp = ts + count - 1
        f = self.frame
        return [f(start + i, ts + i) for i in range(count)]

    def check(self, seqs=(0, 1, 255, 256, 65535, 123457)) -> None:
        """Byte-identical to pymavlink's signed encoding, and accepted by pymavlink holding the key."""
        ts = wall_units()
        receiver = mavlink2.MAVLink(None)
        receiver.signing.secret_key = self.key
        receiver.signing.timestamp = ts  # new streams are checked against this (one-minute window)
        for i, s in enumerate(seqs):
            mine = self.frame(s, ts + i)
            assert mine == self._pymavlink_frame(s, ts + i), f"seq {s}: differs from pymavlink's signed frame"
            msgs = receiver.parse_buffer(mine) or []
            assert len(msgs) == 1 and msgs[0].get_type() == "COMMAND_LONG", f"seq {s}: pymavlink got {msgs!r}"
            assert int(msgs[0].param1) == s, msgs[0]
        assert receiver.signing.goodsig_count == len(seqs) and receiver.signing.badsig_count == 0


def signed_heartbeats(key: bytes, link_id: int):
    """A drop-in for ``frames.heartbeat`` whose HEARTBEATs pymavlink signs (one stream per sysid/compid)."""
    mavs: dict[tuple[int, int], mavlink2.MAVLink] = {}

    def heartbeat(sysid: int, compid: int, mav_type: int, seq: int = 0) -> bytes:
        mav = mavs.get((sysid, compid))
        if mav is None:
            mav = mavs[(sysid, compid)] = _signed_mav(key, sysid, compid, link_id)
        mav.signing.timestamp = max(mav.signing.timestamp, wall_units())
        mav.seq = seq & 0xFF
        return mav.heartbeat_encode(mav_type, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3).pack(mav)

    return heartbeat


def signed_sender_main(conn, key: bytes) -> None:
    from bench import peers

    SignedFrameFactory(key).check()
    peers.FrameFactory = lambda: SignedFrameFactory(key, DATA_LINK_ID)
    peers.heartbeat = signed_heartbeats(key, HEARTBEAT_LINK_ID)
    peers.sender_main(conn)


def signed_receiver_main(conn, key: bytes) -> None:
    from bench import peers

    peers.heartbeat = signed_heartbeats(key, 0)
    peers.receiver_main(conn)


def signed_gcsd_config(workdir, port_a: int, port_b: int, key: bytes = KEY):
    """``routers.routing_gcsd_config`` with signing required on both channels."""
    return gcsd_config(workdir, [
        f'{{name: a, type: udp-server, address: "127.0.0.1:{port_a}", streams: {STREAMS_OFF}}}',
        f'{{name: b, type: udp-server, address: "127.0.0.1:{port_b}", streams: {STREAMS_OFF}}}',
    ], extra=f"vehicle: {{sysid: 1}}\nsigning: {{key: {key.hex()}, require: true}}")


def gcsd_status(cfg, env=None) -> dict[str, dict]:
    """``python -m gcsd status -c CFG --json``: the channels by name."""
    out = subprocess.run([sys.executable, "-m", "gcsd", "status", "-c", str(cfg), "--json"],
                         capture_output=True, text=True, timeout=30, env=env)
    if out.returncode != 0:
        raise RuntimeError(f"gcsd status failed: {out.stderr.strip()}")
    return {ch["name"]: ch for ch in json.loads(out.stdout)["channels"]}


def _rejects(status: dict[str, dict]) -> dict[str, dict[str, int]]:
    return {name: dict(ch.get("signature_reject_reasons", {})) for name, ch in status.items()}


def measure_signing(runner) -> dict:
    """Both figures, unsigned then signed, with ``runner``'s options, peers and sequence numbers."""
    a = runner.a
    res: dict = {}
    cap = runner.res.get("direct", {}).get("throughput")
    max_rate = cap.rate if cap and cap.rate else 200_000

    def search(path: Path):
        sr = measure.search_throughput(path, a.trial_s, a.precision, max_rate=max_rate, confirm=not a.quick)
        if cap and sr.rate >= cap.rate:
            runner.notes.append(f"signing, {path.name}: routed rate reached the harness capacity "
                                "(a lower bound)")
        return sr

    # unsigned: the path of the `throughput` measurement
    log("[signing] gcsd unsigned, as `throughput`")
    try:
        path = runner.router_path("gcsd")
    except (TimeoutError, measure.RouterDied) as exc:
        res["error"] = f"unsigned gcsd: {exc}"
        return res
    try:
        res["unsigned"] = search(path)
    except (measure.RouterDied, TimeoutError) as exc:
        res["error"] = f"unsigned gcsd: {exc}"
    finally:
        res["unsigned_stop"] = path.router.stop()
    if "error" in res:
        return res

    # signed: signing peers, gcsd requiring signatures on both channels
    log("[signing] gcsd with signing required on both channels; signed sender and receiver")
    sender = Peer(signed_sender_main, KEY)
    receiver = Peer(signed_receiver_main, KEY)
    router = None
    try:
        port_a, port_b = free_udp_port(), free_udp_port()
        cfg = signed_gcsd_config(runner.workdir, port_a, port_b)
        router = start_gcsd(runner.workdir, cfg, runner._profile("gcsd-routing-signed.prof"), runner.gcsd_env)
        sender.call("dest", ("127.0.0.1", port_a))
        receiver.call("peer", ("127.0.0.1", port_b), False)
        path = Path("gcsd-signed", sender, receiver, runner.seqs, router,
                    {"router-in": port_a, "receiver": receiver.port, "router-b": port_b},
                    idle_threshold_pct=a.idle_threshold, idle_wait_s=a.idle_wait)
        took = measure.wait_path_ready(path)
        log(f"[gcsd-signed] pid {router.pid}: routing after {took:.2f} s")
        res["signed"] = search(path)
        res["rejects_after_search"] = _rejects(gcsd_status(cfg, runner.gcsd_env))

        # enforcement: the unsigned sender's frames must not get through
        plain_sender, _ = runner.peers()
        plain_sender.call("dest", ("127.0.0.1", port_a))
        try:
            probe = measure.run_trial(Path("unsigned-probe", plain_sender, receiver, runner.seqs, router),
                                      PROBE_RATE, PROBE_S)
        finally:
            plain_sender.call("dest", None)
        rejects = _rejects(gcsd_status(cfg, runner.gcsd_env))
        res["probe"] = {"offered": probe.offered, "delivered": probe.received, "rejects": rejects}
        log(f"[gcsd-signed] unsigned probe: {probe.received} of {probe.offered} delivered; rejects {rejects}")
    except (TimeoutError, measure.RouterDied, RuntimeError) as exc:
        res["error"] = f"signed gcsd: {exc}"
        log(f"[gcsd-signed] FAILED: {exc}")
    finally:
        if router is not None:
            res["signed_stop"] = router.stop()
        sender.close()
        receiver.close()
    if res.get("signed") and res["unsigned"].rate:
        res["ratio"] = res["signed"].rate / res["unsigned"].rate
    return res


def table(res: dict) -> str:
    out = ["Signing: packets routed between two UDP channels, no loss, gcsd unsigned vs signing required "
           "on both channels (bench/signing.py)", ""]
    rows = [("", "pkt/s", "router CPU", "frame")]
    for name, key, size in (("unsigned", "unsigned", 44), ("signed, both channels", "signed", 57)):
        sr = res.get(key)
        if sr is None:
            continue
        cpu = sr.router_cpu_pct
        rows.append((name, f"{sr.rate:,.0f}" + ("" if sr.confirmed or not sr.trials else "*"),
                     "n/a" if cpu is None else f"{cpu:.0f} %", f"{size} B"))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    out += ["  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
            for r in rows]
    if "ratio" in res:
        out.append(f"signed / unsigned: {res['ratio']:.2f}")
    if any(res.get(k) and not res[k].confirmed for k in ("unsigned", "signed")):
        out.append("* not confirmed by a trial twice as long (quick run, or no rate stayed clean)")
    if "rejects_after_search" in res:
        out.append(f"signature rejects after the signed search: {res['rejects_after_search']}")
    if "probe" in res:
        p = res["probe"]
        out.append(f"unsigned probe to the signed gcsd: {p['delivered']} of {p['offered']} delivered; "
                   f"rejects then {p['rejects']}")
    if "error" in res:
        out.append(f"error: {res['error']}")
    return "\n".join(out)
