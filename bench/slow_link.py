"""A 9 600-baud serial link whose default streams want more than its byte budget: how long a
ground station waits for the parameter list and for `@PARAM/param.pck` over FTP, and what the
streams keep meanwhile (scheduler.ServiceShare).

Server: ``python -m gcsd run`` (its own process) with one ``serial`` channel at 9 600 baud on the
slave side of a PTY pair, everything else at its defaults: the copter's 1 000 parameters, the
default SRn_ rates (about 2 000 B/s of telemetry), the channel's budget baud // 10 = 960 B/s. A
PTY has no line speed: the daemon's budget is what paces the link, as on a radio.

Client (this process, the PTY's master side, pymavlink): HEARTBEATs until the vehicle's; then

1. ``streams``: 10 s of nothing asked, the bytes per second of what arrives (the reference);
2. ``param list``: PARAM_REQUEST_LIST, then as MAVProxy does PARAM_REQUEST_READ of up to 10
   missing indices after each second without a new value; the time from the request to the last
   missing value; bytes per second of the streams (everything but PARAM_VALUE, HEARTBEAT and
   STATUSTEXT) and of HEARTBEAT in that window;
3. ``param.pck``: OpenFileRO ``@PARAM/param.pck`` (asked again every 2 s until answered), then
   BurstReadFile from the end of what arrived until the size given at open is covered (a burst
   that goes quiet for 2 s is asked again from its end), TerminateSession; the time from the
   first OpenFileRO to the last byte; the streams' bytes per second in that window; the file is
   decoded with MAVProxy's param.pck reader's format (count of parameters checked).

4. ``mission``: a 30-waypoint mission uploaded (MISSION_COUNT, each MISSION_REQUEST answered
   with its MISSION_ITEM_INT at once, until the MISSION_ACK) and downloaded again
   (MISSION_REQUEST_LIST, then one MISSION_REQUEST_INT per item, each sent when the previous
   item arrived, as MAVProxy and QGroundControl do); each time, and the streams' bytes per
   second during the download. A request not answered within 2 s is sent again.

A step that does not finish within its limit (300 s) is reported as such. Times are the client's
monotonic clock (the reader wakes every 0.1 s at most).

    python bench/slow_link.py                  # gcsd as imported (the working tree)
    python bench/slow_link.py --gcsd-rev REV   # gcsd as committed at REV (git archive REV src)
"""

from __future__ import annotations

import argparse
import os
import select
import shutil
import struct
import sys
import tempfile
import time
import tty
from pathlib import Path

if __package__ in (None, ""):  # run as a script: python bench/slow_link.py
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from pymavlink.dialects.v20 import ardupilotmega as M

from bench.routers import export_gcsd_rev, gcsd_config, gcsd_env, start_gcsd

REPO = Path(__file__).resolve().parent.parent
BAUD = 9600
VEHICLE = (1, 1)
CLIENT = (255, 190)
LIMIT_S = 300.0
QUIET_S = 2.0
BLOCK = 239
OP_TERMINATE, OP_OPEN_RO, OP_BURST, ACK, NAK = 1, 4, 15, 128, 129
HDR = struct.Struct("<HBBBBBxI")
NOT_STREAMS = ("PARAM_VALUE", "HEARTBEAT", "STATUSTEXT", "FILE_TRANSFER_PROTOCOL", "MISSION_COUNT", "MISSION_ITEM_INT",
               "MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK")


class Line:
    """The client's end of the serial line: messages with their arrival times."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.mav = M.MAVLink(None, srcSystem=CLIENT[0], srcComponent=CLIENT[1])
        self.mav.robust_parsing = True
        self.msgs: list[tuple[float, object]] = []

    def send(self, msg) -> None:
        os.write(self.master, msg.pack(self.mav))

    def read(self, seconds: float) -> None:
        if not select.select([self.master], [], [], seconds)[0]:
            return
        try:
            data = os.read(self.master, 65536)
        except (BlockingIOError, InterruptedError):
            return
        now = time.monotonic()
        self.msgs += [(now, m) for m in self.mav.parse_buffer(data) or [] if m.get_type() != "BAD_DATA"]

    def close(self) -> None:
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass


def _rates(line: Line, mark: int, seconds: float) -> tuple[float, float]:
    """(streams, HEARTBEAT) bytes per second among the messages since mark."""
    window = [m for _, m in line.msgs[mark:]]
    streams = sum(len(m.get_msgbuf()) for m in window if m.get_type() not in NOT_STREAMS)
    beats = sum(len(m.get_msgbuf()) for m in window if m.get_type() == "HEARTBEAT")
    return streams / seconds, beats / seconds


def connect(line: Line) -> None:
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline:
        line.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
        line.read(0.5)
        if any(m.get_type() == "HEARTBEAT" and m.get_srcSystem() == VEHICLE[0] for _, m in line.msgs):
            return
    raise TimeoutError("no HEARTBEAT from the vehicle within 30 s")


def streams_alone(line: Line, seconds: float = 10.0) -> dict:
    mark, start = len(line.msgs), time.monotonic()
    while time.monotonic() - start < seconds:
        line.read(0.1)
    total = sum(len(m.get_msgbuf()) for _, m in line.msgs[mark:]) / (time.monotonic() - start)
    streams, beats = _rates(line, mark, time.monotonic() - start)
    return {"seconds": seconds, "total_bps": total, "streams_bps": streams, "heartbeat_bps": beats}


def param_list(line: Line) -> dict:
    mark, start = len(line.msgs), time.monotonic()
    line.send(M.MAVLink_param_request_list_message(*VEHICLE))
    got: set[int] = set()
    count, seen, last_new, rereads = None, mark, start, 0
    while (count is None or len(got) < count) and time.monotonic() - start < LIMIT_S:
        line.read(0.1)
        for _, m in line.msgs[seen:]:
            if m.get_type() == "PARAM_VALUE" and m.get_srcSystem() == VEHICLE[0] and m.param_index not in got:
                count, last_new = m.param_count, time.monotonic()
                got.add(m.param_index)
        seen = len(line.msgs)
        if count is not None and time.monotonic() - last_new > 1.0:
            for i in [i for i in range(count) if i not in got][:10]:
                line.send(M.MAVLink_param_request_read_message(*VEHICLE, b"", i))
                rereads += 1
            last_new = time.monotonic()
    elapsed = time.monotonic() - start
    streams, beats = _rates(line, mark, elapsed)
    return {"done": count is not None and len(got) == count, "values": len(got), "count": count,
            "seconds": elapsed, "rereads": rereads, "streams_bps": streams, "heartbeat_bps": beats}


class Ftp:
    def __init__(self, line: Line) -> None:
        self.line = line
        self.seq = 0
        self.seen = len(line.msgs)

    def request(self, opcode: int, size: int = 0, offset: int = 0, data: bytes = b"", session: int = 0) -> None:
        payload = HDR.pack(self.seq, session, opcode, size, 0, 0, offset) + data
        self.seq = (self.seq + 1) & 0xFFFF
        self.line.send(M.MAVLink_file_transfer_protocol_message(0, *VEHICLE, payload.ljust(251, b"\0")))

    def replies(self):
        self.line.read(0.1)
        for _, m in self.line.msgs[self.seen:]:
            if m.get_type() == "FILE_TRANSFER_PROTOCOL" and m.get_srcSystem() == VEHICLE[0]:
                body = bytes(m.payload)
                yield HDR.unpack_from(body), body[12:]
        self.seen = len(self.line.msgs)


def param_pck(line: Line) -> dict:
    mark, start = len(line.msgs), time.monotonic()
    ftp = Ftp(line)
    name = b"@PARAM/param.pck"
    size = session = None
    asked = 0.0
    while size is None and time.monotonic() - start < LIMIT_S:
        if time.monotonic() - asked > QUIET_S:
            ftp.request(OP_OPEN_RO, len(name), 0, name)
            asked = time.monotonic()
        for (_, sess, op, _, req, _, _), data in ftp.replies():
            if req == OP_OPEN_RO and op == ACK:
                size, session = struct.unpack_from("<I", data)[0], sess
    opened_s = time.monotonic() - start
    out = bytearray(size or 0)
    have = bytearray(((size or 0) + BLOCK - 1) // BLOCK + 1)
    top = 0
    burst_open, last = False, time.monotonic()
    while size is not None and top < size and time.monotonic() - start < LIMIT_S:
        if not burst_open or time.monotonic() - last > QUIET_S:
            ftp.request(OP_BURST, BLOCK, top, session=session)
            burst_open, last = True, time.monotonic()
        for (_, _, op, sz, req, complete, offset), data in ftp.replies():
            if req != OP_BURST:
                continue
            last = time.monotonic()
            if op == ACK:
                out[offset:offset + sz] = data[:sz]
                have[offset // BLOCK] = 1
                while top < size and have[top // BLOCK]:
                    top = min(size, (top // BLOCK + 1) * BLOCK)
            if complete or op == NAK:
                burst_open = False
    elapsed = time.monotonic() - start
    if session is not None:
        ftp.request(OP_TERMINATE, session=session)
    streams, beats = _rates(line, mark, elapsed)
    done = size is not None and top >= size
    params = struct.unpack_from("<HH", out, 2)[0] if done and len(out) >= 6 else None  # magic, num_params
    return {"done": done, "size": size, "opened_s": opened_s, "seconds": elapsed, "params": params,
            "streams_bps": streams, "heartbeat_bps": beats}


def _await(line: Line, seen: int, match, resend, limit_s: float):
    """The first message since `seen` that matches, calling resend() every 2 s without one."""
    start, sent = time.monotonic(), time.monotonic()
    while time.monotonic() - start < limit_s:
        line.read(0.1)
        found = [m for _, m in line.msgs[seen:] if m.get_srcSystem() == VEHICLE[0] and match(m)]
        if found:
            return found[0]
        if time.monotonic() - sent > QUIET_S:
            resend()
            sent = time.monotonic()
    return None


def mission(line: Line, items: int = 30) -> dict:
    def request(seq: int) -> None:
        line.send(M.MAVLink_mission_request_int_message(*VEHICLE, seq, M.MAV_MISSION_TYPE_MISSION))

    start = time.monotonic()
    count = M.MAVLink_mission_count_message(*VEHICLE, items, M.MAV_MISSION_TYPE_MISSION)
    seen = len(line.msgs)
    line.send(count)
    done = set()
    ack = None
    while ack is None and time.monotonic() - start < LIMIT_S:
        m = _await(line, seen, lambda m: m.get_type() in ("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"),
                   lambda: None, QUIET_S * 4)
        if m is None:
            break
        seen = len(line.msgs)
        if m.get_type() == "MISSION_ACK":
            ack = m.type
            break
        done.add(m.seq)
        line.send(M.MAVLink_mission_item_int_message(*VEHICLE, m.seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                                     M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0,
                                                     int(-35.36e7) + m.seq, int(149.16e7), 20.0))
    up_s = time.monotonic() - start
    mark, start = len(line.msgs), time.monotonic()
    seen = mark
    listing = M.MAVLink_mission_request_list_message(*VEHICLE, M.MAV_MISSION_TYPE_MISSION)
    line.send(listing)
    got = _await(line, seen, lambda m: m.get_type() == "MISSION_COUNT", lambda: line.send(listing), LIMIT_S)
    received = 0
    for seq in range(got.count if got is not None else 0):
        seen = len(line.msgs)
        request(seq)
        item = _await(line, seen, lambda m, seq=seq: m.get_type() == "MISSION_ITEM_INT" and m.seq == seq,
                      lambda seq=seq: request(seq), LIMIT_S)
        if item is None:
            break
        received += 1
    down_s = time.monotonic() - start
    streams, beats = _rates(line, mark, down_s)
    return {"items": items, "up_ack": ack, "up_s": up_s, "down_items": received, "down_s": down_s,
            "streams_bps": streams, "heartbeat_bps": beats}


def measure(workdir: Path, env: dict | None) -> dict:
    line = Line()
    cfg = gcsd_config(workdir, [f'{{name: radio, type: serial, device: "{line.path}", baud: {BAUD}}}'])
    server = start_gcsd(workdir, cfg, env=env)
    try:
        connect(line)
        return {"streams": streams_alone(line), "param list": param_list(line), "param.pck": param_pck(line),
                "mission": mission(line)}
    finally:
        print(f"gcsd {server.stop()}", file=sys.stderr)
        line.close()


def table(res: dict) -> str:
    s, p, f, w = res["streams"], res["param list"], res["param.pck"], res["mission"]
    late = {True: "", False: "unfinished after "}
    rows = [
        "| step | time | streams kept | HEARTBEAT |",
        "|---|---:|---:|---:|",
        (f"| nothing asked (10 s) | - | {s['streams_bps']:.0f} B/s (link total {s['total_bps']:.0f} B/s) | "
         f"{s['heartbeat_bps']:.0f} B/s |"),
        (f"| PARAM_REQUEST_LIST, {p['values']} of {p['count']} values ({p['rereads']} re-read) | "
         f"{late[p['done']]}{p['seconds']:.1f} s | {p['streams_bps']:.0f} B/s | {p['heartbeat_bps']:.0f} B/s |"),
        (f"| FTP @PARAM/param.pck, {f['size']} B ({f['params']} parameters), open answered after "
         f"{f['opened_s']:.1f} s | {late[f['done']]}{f['seconds']:.1f} s | {f['streams_bps']:.0f} B/s | "
         f"{f['heartbeat_bps']:.0f} B/s |"),
        (f"| mission of {w['items']} waypoints: upload (ACK {w['up_ack']}) | {w['up_s']:.1f} s | | |"),
        (f"| mission: download, {w['down_items']} items | {w['down_s']:.1f} s | {w['streams_bps']:.0f} B/s | "
         f"{w['heartbeat_bps']:.0f} B/s |"),
    ]
    return "\n".join(rows)


def main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="python bench/slow_link.py", description=__doc__.split("\n")[0])
    p.add_argument("--gcsd-rev", help="gcsd as committed at REV (git archive REV src)")
    a = p.parse_args(argv)
    workdir = Path(tempfile.mkdtemp(prefix="gcsd-bench-slow-link-"))
    try:
        env, what = None, "the working tree"
        if a.gcsd_rev:
            src, what = export_gcsd_rev(REPO, a.gcsd_rev, workdir / "rev")
            env = gcsd_env(src)
        print(f"gcsd: {what}", file=sys.stderr)
        res = measure(workdir, env)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    print(table(res))
    ok = res["mission"]["down_items"] == res["mission"]["items"] and res["mission"]["up_ack"] == 0
    return 0 if res["param list"]["done"] and res["param.pck"]["done"] and ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
