"""CAN over MAVLink through gcsd: the round trip of a DroneCAN request and the daemon's CPU cost.

`python -m bench.can_bridge [--samples N] [--cpu-s S]`: starts `gcsd run` (a subprocess, the
product's defaults plus one `virtual` bus with the simulated gps and battery nodes, a UDP server
channel on loopback), then, as a pymavlink ground station (MAVLink2):
1. round trip: MAV_CMD_CAN_FORWARD for bus 1 (repeated every second, as pydronecan does), then N
   times a uavcan.protocol.GetNodeInfo request to node 10 as one CAN_FRAME; the time from sending
   it to the CAN_FRAME that ends the response (tail byte end-of-transfer, from node 10) arriving:
   the bridge's write to the bus, the node's answer, the bridge's poll (every 10 ms) and the UDP hops;
2. CPU: the daemon's user+system time over S seconds with the ground station connected and not
   forwarding, then S seconds while it forwards (the bridge polls the bus every 10 ms and sends
   every frame of the nodes: NodeStatus 1 Hz each, Fix2 5 Hz, BatteryInfo 1 Hz), from /proc.
Prints the figures; bench/RESULTS.md records them with the date and the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as M

NODE = 10
LOCAL_NODE = 127
GET_NODE_INFO = 1


def _request_id(transfer_id: int) -> tuple[int, bytes]:
    """A single-frame GetNodeInfo request (empty payload) from LOCAL_NODE to NODE: CAN id and data."""
    can_id = (1 << 31) | (30 << 24) | (GET_NODE_INFO << 16) | (1 << 15) | (NODE << 8) | 0x80 | LOCAL_NODE
    return can_id, bytes([0xC0 | (transfer_id & 0x1F)])  # tail: start, end, toggle 0


def _start(tmp: Path) -> tuple[subprocess.Popen, int]:
    config = tmp / "gcsd.yaml"
    config.write_text(f"state_dir: {tmp / 'state'}\nlog: {{level: info, format: json}}\n"
                      "channels:\n  - {name: gcs, type: udp-server, address: '127.0.0.1:0'}\n"
                      "can:\n  buses:\n"
                      f"    - {{interface: virtual, channel: bench-{os.getpid()}, nodes: [gps, battery]}}\n")
    log = tmp / "gcsd.log"
    proc = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(config)], stdout=log.open("wb"),
                            stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        for line in log.read_text(errors="replace").splitlines():
            if '"channel_opened"' in line and '"gcs"' in line:
                return proc, int(json.loads(line)["address"].rsplit(":", 1)[1])
        time.sleep(0.1)
    proc.kill()
    raise RuntimeError("gcsd did not open its channel")


def _cpu_s(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=200)
    ap.add_argument("--cpu-s", type=float, default=20.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        proc, port = _start(Path(tmp))
        try:
            conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=250, source_component=189)
            conn.mav = M.MAVLink(conn, srcSystem=250, srcComponent=189)
            conn.first_byte = False
            conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
            # CPU, not forwarding
            t0, c0 = time.monotonic(), _cpu_s(proc.pid)
            while time.monotonic() - t0 < args.cpu_s:
                conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                conn.recv_match(blocking=True, timeout=1.0)
                while conn.recv_match(blocking=False) is not None:
                    pass
            idle_pct = 100 * (_cpu_s(proc.pid) - c0) / (time.monotonic() - t0)
            # round trips
            forward_s = 0.0
            rtts, frames = [], 0
            for n in range(args.samples):
                if time.monotonic() - forward_s > 1.0:
                    conn.mav.command_long_send(1, 0, M.MAV_CMD_CAN_FORWARD, 0, 1, 0, 0, 0, 0, 0, 0)
                    forward_s = time.monotonic()
                can_id, data = _request_id(n)
                sent = time.perf_counter()
                conn.mav.can_frame_send(1, 0, 0, len(data), can_id, data.ljust(8, b"\0"))
                deadline = time.monotonic() + 2.0
                while time.monotonic() < deadline:
                    m = conn.recv_match(type="CAN_FRAME", blocking=True, timeout=0.5)
                    if m is None:
                        continue
                    frames += 1
                    is_response_end = (m.id & 0x7F) == NODE and (m.id >> 16) & 0xFF == GET_NODE_INFO and \
                        not (m.id >> 15) & 1 and m.len and m.data[m.len - 1] & 0x40
                    if is_response_end:
                        rtts.append((time.perf_counter() - sent) * 1000)
                        break
            # CPU, forwarding
            t0, c0 = time.monotonic(), _cpu_s(proc.pid)
            while time.monotonic() - t0 < args.cpu_s:
                if time.monotonic() - forward_s > 1.0:
                    conn.mav.command_long_send(1, 0, M.MAV_CMD_CAN_FORWARD, 0, 1, 0, 0, 0, 0, 0, 0)
                    forward_s = time.monotonic()
                if conn.recv_match(blocking=True, timeout=0.2) is not None:
                    frames += 1
            forwarding_pct = 100 * (_cpu_s(proc.pid) - c0) / (time.monotonic() - t0)
        finally:
            proc.terminate()
            proc.wait(10)
    rtts.sort()
    print(f"GetNodeInfo round trips: {len(rtts)}/{args.samples}, median {statistics.median(rtts):.1f} ms, "
          f"p95 {rtts[int(0.95 * (len(rtts) - 1))]:.1f} ms, max {rtts[-1]:.1f} ms")
    print(f"daemon CPU: {idle_pct:.1f} % of a core with a ground station, {forwarding_pct:.1f} % while it forwards "
          f"the bus ({args.cpu_s:.0f} s each)")
    return 0 if len(rtts) == args.samples else 1


if __name__ == "__main__":
    sys.exit(main())
