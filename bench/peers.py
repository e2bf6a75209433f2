"""Traffic sender and receiver, each in its own process, driven over a multiprocessing Pipe.

Both are plain UDP sockets on 127.0.0.1.  Every command sent to a peer gets exactly one reply, so the
parent uses them as synchronous calls (``Peer.call``).

Sender (sysid 200): ``dest`` sets where packets go; ``prepare`` pre-encodes the frames of one trial
(so encoding is not timed); ``run`` sends them paced at ``rate`` packets/s: it sends every packet
that is due, then sleeps until the next deadline but at least ``min_sleep_s`` (so at high rates
packets go out in batches of about ``rate * min_sleep_s``; with ``min_sleep_s = 0`` each packet is
sent on its own deadline).  It never busy-waits.  With ``stamp`` it records ``perf_counter_ns()`` just before each ``sendto`` in a dict
keyed by seq.  HEARTBEAT (MAV_TYPE_GCS) to ``dest`` once a second, during runs too.

Receiver (sysid 250, compid 1): a non-blocking socket with a 4 MiB SO_RCVBUF, drained in a tight loop
of ``recv_into``; when empty it waits in ``select`` on the socket and the control pipe.  Frames are
counted by walking MAVLink headers (no payload decode) and only COMMAND_LONG from sysid 200 counts;
the router's own HEARTBEATs and forwarded heartbeats are tallied as ``other``.  Per trial it keeps a
bytearray of seen seqs, so loss, duplicates and reordering are exact; packets with a seq outside the
trial's range are ``stale``.  With ``stamp`` it records ``perf_counter_ns()`` right after
``recv_into`` (CLOCK_MONOTONIC, comparable across processes).  HEARTBEAT once a second to ``peer``,
or, with ``learn``, to whoever sent the first datagram (a router whose output port is not known).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import select
import socket
import struct
import time

from bench.frames import (
    MSGID_COMMAND_LONG,
    SENDER_COMPID,
    SENDER_SYSID,
    TARGET_COMPID,
    TARGET_SYSID,
    FrameFactory,
    heartbeat,
)

MAV_TYPE_GCS = 6
MAV_TYPE_ONBOARD_CONTROLLER = 18
RCVBUF_BYTES = 4 * 1024 * 1024
HEARTBEAT_PERIOD_S = 1.0


def _big_buffers(sock: socket.socket) -> int:
    for opt in (getattr(socket, "SO_RCVBUFFORCE", None), socket.SO_RCVBUF):
        if opt is None:
            continue
        try:
            sock.setsockopt(socket.SOL_SOCKET, opt, RCVBUF_BYTES)
            break
        except OSError:
            continue
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, RCVBUF_BYTES)
    return sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)


# ----------------------------------------------------------------------------------------- sender


def sender_main(conn) -> None:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    _big_buffers(sock)
    factory = FrameFactory()
    dest = None
    hb_seq = 0
    next_hb = 0.0
    frames: list[bytes] = []
    frames_lo = 0
    conn.send(("ready", sock.getsockname()[1], os.getpid()))

    def beat(now: float) -> float:
        nonlocal hb_seq
        if dest is not None:
            sock.sendto(heartbeat(SENDER_SYSID, SENDER_COMPID, MAV_TYPE_GCS, hb_seq), dest)
            hb_seq += 1
        _drain_discard(sock)
        return now + HEARTBEAT_PERIOD_S

    while True:
        now = time.monotonic()
        if now >= next_hb:
            next_hb = beat(now)
        if not conn.poll(max(0.0, next_hb - now)):
            continue
        cmd, *args = conn.recv()
        if cmd == "quit":
            conn.send(("ok",))
            return
        if cmd == "dest":
            dest = tuple(args[0]) if args[0] else None
            next_hb = 0.0
            conn.send(("ok",))
        elif cmd == "hb":
            next_hb = beat(time.monotonic())
            conn.send(("ok",))
        elif cmd == "get_dest":
            conn.send(("dest", dest))
        elif cmd == "prepare":
            frames_lo, count = args
            frames = factory.frames(frames_lo, count)
            conn.send(("ok",))
        elif cmd == "run":
            lo, count, rate, stamp, min_sleep_s = args
            if lo != frames_lo or len(frames) != count:
                frames, frames_lo = factory.frames(lo, count), lo
            result, next_hb = _paced_send(sock, dest, frames, lo, rate, stamp, min_sleep_s, next_hb, beat)
            frames = []
            conn.send(("done", result))
        else:
            conn.send(("error", f"unknown command {cmd}"))


def _drain_discard(sock: socket.socket) -> None:
    try:
        while True:
            sock.recv(65536, socket.MSG_DONTWAIT)
    except (BlockingIOError, InterruptedError):
        pass
    except OSError:
        pass  # e.g. ECONNREFUSED from an ICMP port-unreachable; harmless


def _paced_send(sock, dest, frames, lo, rate, stamp, min_sleep_s, next_hb, beat):
    send = sock.sendto
    perf = time.perf_counter
    perf_ns = time.perf_counter_ns
    sleep = time.sleep
    count = len(frames)
    stamps = {} if stamp else None
    errors = 0
    max_lag_s = 0.0
    period = 1.0 / rate
    t0 = perf()
    i = 0
    while i < count:
        now = perf()
        due = min(count, int((now - t0) * rate) + 1)
        if due > i:
            lag = now - (t0 + i * period)
            max_lag_s = max(max_lag_s, lag)
            while i < due:
                try:
                    if stamps is not None:
                        stamps[lo + i] = perf_ns()
                    send(frames[i], dest)
                except OSError:
                    errors += 1
                i += 1
            mono = time.monotonic()
            if mono >= next_hb:
                next_hb = beat(mono)
            continue
        # Not due yet: sleep (never spin: sender, receiver and router share two cores).
        sleep(max(t0 + i * period - now, min_sleep_s))
    elapsed = perf() - t0
    return (
        {
            "sent": count - errors,
            "errors": errors,
            "elapsed_s": elapsed,
            "rate_achieved": count / elapsed if elapsed > 0 else float("inf"),
            "max_lag_s": max_lag_s,
            "stamps": stamps,
        },
        next_hb,
    )


# --------------------------------------------------------------------------------------- receiver


class _Trial:
    __slots__ = (
        "bad",
        "datagrams",
        "dup",
        "first_ns",
        "last",
        "last_ns",
        "lo",
        "other",
        "reorder",
        "seen",
        "span",
        "stale",
        "stamps",
        "uniq",
    )

    def __init__(self, lo: int = 0, span: int = 0, stamp: bool = False) -> None:
        self.lo, self.span = lo, span
        self.seen = bytearray(span)
        self.uniq = self.dup = self.reorder = self.stale = self.other = self.bad = self.datagrams = 0
        self.last = -1
        self.stamps = {} if stamp else None
        self.first_ns = self.last_ns = 0

    def report(self) -> dict:
        return {k: getattr(self, k) for k in self.__slots__ if k != "seen"}


def _drain(sock: socket.socket, buf: bytearray, t: _Trial, learn_addr: bool):
    """Receive and count until the socket is empty or 4096 datagrams; return (empty, first_addr)."""
    recv_into = sock.recv_into
    unpack_f = struct.Struct("<f").unpack_from
    perf_ns = time.perf_counter_ns
    lo, span, seen, stamps = t.lo, t.span, t.seen, t.stamps
    uniq, dup, reorder, last, stale, other, bad, dgrams = (
        t.uniq, t.dup, t.reorder, t.last, t.stale, t.other, t.bad, t.datagrams)
    addr = None
    empty = False
    now_ns = 0
    k = 0
    try:
        while k < 4096:
            if learn_addr and addr is None:
                n, addr = sock.recvfrom_into(buf)
            else:
                n = recv_into(buf)
            now_ns = perf_ns()
            k += 1
            off = 0
            while off + 8 <= n:
                stx = buf[off]
                if stx == 0xFD:
                    flen = 12 + buf[off + 1] + (13 if buf[off + 2] & 1 else 0)
                    mine = (buf[off + 5] == SENDER_SYSID and buf[off + 7] == MSGID_COMMAND_LONG
                            and buf[off + 8] == 0 and buf[off + 9] == 0)
                    pay = off + 10
                elif stx == 0xFE:
                    flen = 8 + buf[off + 1]
                    mine = buf[off + 3] == SENDER_SYSID and buf[off + 5] == MSGID_COMMAND_LONG
                    pay = off + 6
                else:
                    bad += 1
                    break
                if off + flen > n:
                    bad += 1
                    break
                if mine:
                    seq = int(unpack_f(buf, pay)[0])
                    i = seq - lo
                    if 0 <= i < span:
                        if seen[i]:
                            dup += 1
                        else:
                            seen[i] = 1
                            uniq += 1
                            if stamps is not None:
                                stamps[seq] = now_ns
                        if seq < last:
                            reorder += 1
                        last = seq
                    else:
                        stale += 1
                else:
                    other += 1
                off += flen
    except (BlockingIOError, InterruptedError):
        empty = True
    except ConnectionRefusedError:
        empty = True
    dgrams += k
    if t.first_ns == 0 and uniq:
        t.first_ns = now_ns
    if uniq != t.uniq:
        t.last_ns = now_ns
    t.uniq, t.dup, t.reorder, t.last, t.stale, t.other, t.bad, t.datagrams = (
        uniq, dup, reorder, last, stale, other, bad, dgrams)
    return empty, addr


def receiver_main(conn, bind_port: int = 0) -> None:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", bind_port))
    rcvbuf = _big_buffers(sock)
    sock.setblocking(False)
    buf = bytearray(65536)
    trial = _Trial()
    peer = None
    learn = False
    hb_seq = 0
    next_hb = 0.0
    extra: list[bytes] = []  # more frames sent with each HEARTBEAT ("extra": bench/routes.py's fleet)
    conn.send(("ready", sock.getsockname()[1], os.getpid(), rcvbuf))
    while True:
        empty, addr = _drain(sock, buf, trial, learn and peer is None)
        if addr is not None and learn and peer is None:
            peer = addr
            next_hb = 0.0
        now = time.monotonic()
        if now >= next_hb:
            if peer is not None:
                try:
                    sock.sendto(heartbeat(TARGET_SYSID, TARGET_COMPID, MAV_TYPE_ONBOARD_CONTROLLER, hb_seq), peer)
                    for raw in extra:
                        sock.sendto(raw, peer)
                except OSError:
                    pass
                hb_seq += 1
            next_hb = now + HEARTBEAT_PERIOD_S
        if empty:
            ready, _, _ = select.select([sock, conn], [], [], max(0.0, next_hb - now))
            if conn not in ready:
                continue
        elif not conn.poll():
            continue
        cmd, *args = conn.recv()
        if cmd == "quit":
            conn.send(("ok",))
            return
        if cmd == "peer":
            peer = tuple(args[0]) if args[0] else None
            learn = bool(args[1])
            next_hb = 0.0
            conn.send(("ok",))
        elif cmd == "hb":
            next_hb = 0.0
            conn.send(("ok",))
        elif cmd == "extra":
            extra = list(args[0])
            next_hb = 0.0
            conn.send(("ok",))
        elif cmd == "reset":
            lo, span, stamp = args
            trial = _Trial(lo, span, stamp)
            conn.send(("ok",))
        elif cmd == "count":
            conn.send(("count", trial.uniq))
        elif cmd == "report":
            conn.send(("report", trial.report()))
        else:
            conn.send(("error", f"unknown command {cmd}"))


# ----------------------------------------------------------------------------------------- parent


class Peer:
    """A sender or receiver process and its control pipe."""

    def __init__(self, target, *args) -> None:
        ctx = mp.get_context("spawn")
        self.conn, child = ctx.Pipe()
        self.proc = ctx.Process(target=target, args=(child, *args), daemon=True)
        self.proc.start()
        if not self.conn.poll(30):
            raise RuntimeError(f"{target.__name__} did not start")
        ready = self.conn.recv()
        self.port, self.pid = ready[1], ready[2]
        self.info = ready[3:]

    def call(self, *cmd, timeout: float = 600.0):
        self.conn.send(cmd)
        if not self.conn.poll(timeout):
            raise TimeoutError(f"no reply to {cmd[0]}")
        reply = self.conn.recv()
        if reply[0] == "error":
            raise RuntimeError(reply[1])
        return reply[1] if len(reply) > 1 else None

    def close(self) -> None:
        try:
            if self.proc.is_alive():
                self.call("quit", timeout=5)
        except (OSError, EOFError, TimeoutError):
            pass
        self.proc.join(5)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join(5)


def start_sender() -> Peer:
    return Peer(sender_main)


def start_receiver(bind_port: int = 0) -> Peer:
    return Peer(receiver_main, bind_port)
