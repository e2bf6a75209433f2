"""What a big route table costs a running router (SPEC.md "Performance": with 250 learned routes,
CPU per routed packet within 10 % of the figure with 20), gcsd and mavlink-router side by side.

Run: ``python -m bench routes`` (about 3 minutes; ``--quick`` about 40 s); ``--routers`` as usual
(gcsd and mavlink-router are measured; MAVProxy keeps no route table).

The routing harness of bench/README.md (sender -> channel/endpoint `a` -> `b` -> receiver,
COMMAND_LONG from 200/190 to 250/1, one frame per datagram) at a fixed, loss-free RATE. Before a
trial the receiver (on `b`'s side) sends one HEARTBEAT from each of N more systems (sysid 2..,
compid 1, MAV_TYPE_QUADROTOR) with its own, so the router has learned N more routes on that
channel, as a fleet ground side or an MQTT bridge holds them: N = 18 (20 routes with the
sender's and the receiver's) or 248 (250 routes); they go again every second during the trial
so that none expires. Each round runs, for each router, 20 then 250 routes (a new router
process each); CPU per packet = the router's CPU over the trial / packets received. Reported per
router: the median of the rounds for each table size, and the median of the rounds' ratios
(250 / 20 of the same round: back to back, so they share the machine's load).
"""

from __future__ import annotations

import statistics

from pymavlink.dialects.v20 import ardupilotmega as M

from bench import measure
from bench.measure import log

RATE = 15000
TRIAL_S, QUICK_TRIAL_S = 6.0, 2.0
ROUNDS, QUICK_ROUNDS = 5, 2
SIZES = (20, 250)
KNOWN = 2  # the routes every trial has: the sender (200/190) and the receiver (250/1)


def _heartbeats(n: int) -> list[bytes]:
    out = []
    for sysid in range(2, 2 + n):
        mav = M.MAVLink(None, srcSystem=sysid, srcComponent=1)
        out.append(M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 4, 3)
                   .pack(mav))
    return out


class Fleet:
    """N systems heard on the router's `b` side, sent by the receiver with its HEARTBEAT every
    second, from its own socket: a UDP server endpoint of mavlink-router answers only the last
    address it heard, so the fleet must not move it."""

    def __init__(self, receiver, n: int) -> None:
        self.receiver = receiver
        receiver.call("extra", _heartbeats(n))

    def close(self) -> None:
        self.receiver.call("extra", [])


def measure_routes(runner) -> dict:
    quick = runner.a.quick
    routers = [r for r in ("gcsd", "mavlink-router") if r in runner.a.routers
               and (r != "mavlink-router" or runner.mavlink_router)]
    us = {r: {n: [] for n in SIZES} for r in routers}
    lost = {r: 0 for r in routers}
    others: list[float] = []
    for _ in range(QUICK_ROUNDS if quick else ROUNDS):
        for router in routers:
            for n in SIZES:
                path = runner.router_path(router)
                fleet = Fleet(path.receiver, n - KNOWN)
                try:
                    measure.wait_path_ready(path)
                    t = measure.run_trial_retrying(path, RATE, QUICK_TRIAL_S if quick else TRIAL_S)
                finally:
                    fleet.close()
                    path.router.stop()
                log(f"  [routes {router} {n}] {t.line()}")
                if t.received:
                    us[router][n].append(t.cpu_pct["router"] / 100 * (t.offered / RATE) / t.received * 1e6)
                lost[router] += t.lost
                others.append(t.other_cpu_pct)
    res = {"rate": RATE, "us_per_packet": us, "lost": lost, "other_cpu_max_pct": max(others, default=0.0)}
    for router in routers:
        small, big = us[router][SIZES[0]], us[router][SIZES[1]]
        ratios = [b / s for s, b in zip(small, big)]
        res[router] = {"small_us": statistics.median(small) if small else None,
                       "big_us": statistics.median(big) if big else None,
                       "ratio": statistics.median(ratios) if ratios else None, "ratios": ratios}
    return res


def table(res: dict) -> str:
    lines = [(f"Route table size (bench/routes.py): CPU per routed packet at {res['rate']} pkt/s, "
              f"{SIZES[0]} against {SIZES[1]} learned routes (medians of the rounds)")]
    for router, r in res.items():
        if not isinstance(r, dict) or "ratio" not in r:
            continue
        if r["ratio"] is None:
            lines.append(f"  {router}: no figure (no trial got through)")
            continue
        ok = "yes" if r["ratio"] <= 1.10 else "NO"
        lines.append(f"  {router}: {r['small_us']:.2f} us with {SIZES[0]}, {r['big_us']:.2f} us with {SIZES[1]}; "
                     f"median ratio {r['ratio']:.3f} (SPEC <= 1.10: {ok}); rounds "
                     + ", ".join(f"{x:.2f}" for x in r["ratios"]))
    lines.append(f"  packets lost: {res['lost']}; max CPU of other processes during a trial: "
                 f"{res['other_cpu_max_pct']:.0f} % of one core")
    return "\n".join(lines)
