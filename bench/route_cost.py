"""What routing one frame costs in process, with no sockets: Channel.receive -> routing -> the
peer's writer, as `_Datagram._read_ready` drives it.

Run: ``python -m bench.route_cost`` (about 20 s, one core), or against another revision with
``PYTHONPATH=<git archive REV src>/src python bench/route_cost.py``.

Setup: the daemon object (GCS) from the bench's routing configuration (two udp-server channels
`a` and `b`, stream rates 0), not started. A receiver peer on `b` sends a HEARTBEAT as (250, 1),
which teaches the route; a sender peer on `a` sends HEARTBEAT as (200, 190). Then N COMMAND_LONG
datagrams (44 bytes, MAVLink2, distinct sequence numbers in param1, as bench/frames.py) from
(200, 190) to (250, 1) go through `Channel.receive(peer, data, now, datagram=True)`, in batches
of 64 with one `now` per batch (the transport's rule), and the receiver's writer counts what it
gets. Timed: process CPU time for the N frames, best of 5 runs; reported as microseconds per
routed frame. Also 20 routes with the HTTP API off (`http.address: null`; on by default, it taps every frame).
"250 routes": first 248 more sources (sysid 2..249 on `b`, compid 1) are learned,
so the table holds 250 routes, as a fleet ground side does.
"""

from __future__ import annotations

import platform
import sys
import time

import yaml
from pymavlink.dialects.v20 import ardupilotmega as M

N = 100_000
RUNS = 5
BATCH = 64


def _config(tmp: str, routes: int, extra: dict | None = None):
    extra = extra or {}
    from gcsd.config import parse_config

    streams = {name: 0 for name in ("raw_sens", "ext_stat", "rc_chan", "raw_ctrl", "position", "extra1",
                                    "extra2", "extra3", "params", "adsb")}
    data = {"state_dir": tmp, "log": {"level": "warning"}, **extra,
            "channels": [{"name": "a", "type": "udp-server", "address": "127.0.0.1:0", "streams": streams},
                         {"name": "b", "type": "udp-server", "address": "127.0.0.1:0", "streams": streams}]}
    if routes > 20:
        data["channels"].append({"name": "fleet", "type": "mqtt", "broker": "mqtt://127.0.0.1:1", "topic": "t",
                                 "role": "ground"})
    return parse_config(yaml.safe_dump(data), "bench.yaml")


def _frames(count: int) -> list[bytes]:
    mav = M.MAVLink(None, srcSystem=200, srcComponent=190)
    out = []
    for i in range(count):
        msg = M.MAVLink_command_long_message(250, 1, M.MAV_CMD_USER_1, 0, float(i), 0, 0, 0, 0, 0, 0)
        out.append(bytes(msg.pack(mav)))
        mav.seq = (mav.seq + 1) & 0xFF
    return out


def _heartbeat(sysid: int, compid: int, mav_type: int = M.MAV_TYPE_GCS) -> bytes:
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    return bytes(M.MAVLink_heartbeat_message(mav_type, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3).pack(mav))


def measure(routes: int, extra: dict | None = None) -> tuple[float, int]:
    import tempfile

    from gcsd.daemon.daemon import Daemon

    with tempfile.TemporaryDirectory() as tmp:
        gcs = Daemon(_config(tmp, routes, extra))
        a, b = gcs.channels[0], gcs.channels[1]
        got = [0]

        def receiver(data: bytes) -> bool:
            got[0] += 1
            return True

        sender = a.add_peer(("127.0.0.1", 1), lambda data: True, 0.0)
        rx = b.add_peer(("127.0.0.1", 2), receiver, 0.0)
        now = 1.0
        b.receive(rx, _heartbeat(250, 1, M.MAV_TYPE_QUADROTOR), now, datagram=True)
        for sysid in range(2, routes):  # sysid 1 is our own vehicle
            b.receive(rx, _heartbeat(sysid, 1, M.MAV_TYPE_QUADROTOR), now, datagram=True)
        a.receive(sender, _heartbeat(200, 190), now, datagram=True)
        assert len(gcs.router.table) >= routes, (len(gcs.router.table), routes)
        frames = _frames(N)
        receive = a.receive
        best = float("inf")
        for _ in range(RUNS):
            got[0] = 0
            start = time.process_time()
            for i in range(0, N, BATCH):
                now += 0.001
                for raw in frames[i:i + BATCH]:
                    receive(sender, raw, now, True)
            best = min(best, time.process_time() - start)
            now += 10.0  # past any loop/duplicate window: the next run's frames are new again
        return best / N * 1e6, got[0]


def main() -> None:
    print(f"# route_cost: Python {platform.python_version()}, {platform.machine()}, N={N}, best of {RUNS}")
    for routes in (20, 250):
        us, got = measure(routes)
        print(f"{routes:>4} routes: {us:6.2f} us per routed frame (the receiver got {got} of {N})")
    if "http" in _config("/tmp", 20).__dataclass_fields__:  # the HTTP API's tap on every frame, off
        us, got = measure(20, {"http": {"address": None}})
        print(f"  20 routes, http.address null: {us:6.2f} us per routed frame")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
