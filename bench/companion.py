"""What companion routing's filters and rate caps cost per routed packet (SPEC.md "Performance":
a channel with filters and rate caps, <= 10 % more CPU per packet than without).

Run: ``python -m bench companion --routers gcsd`` (about 1 minute; ``--quick`` about 20 s).

The routing harness of bench/README.md (sender -> gcsd channel `a` -> channel `b` -> receiver,
COMMAND_LONG from 200/190 to 250/1, one frame per datagram) at a fixed, loss-free rate
(RATE pkt/s), with two configurations of the same two udp-server channels:
- plain: as the routing benchmark;
- gated: `a` has an in filter (block_msgids [PARAM_VALUE, SERIAL_CONTROL], block_src_sys [99]),
  `b` an out filter (allow_src_sys [1, 200, 250], block_msgids [ATTITUDE_QUATERNION]) and rate
  caps (ATTITUDE 10, GLOBAL_POSITION_INT 5, VFR_HUD 4): every routed frame is checked by both
  filters and looked up in the caps, and passes (COMMAND_LONG is not capped), as the bulk of a
  companion's traffic does.
Each round runs plain then gated (a new gcsd each), one trial of TRIAL_S at RATE; gcsd's CPU over
the trial divided by the packets received is the CPU per packet. Reported: the median of the
rounds for each, and the median of the rounds' ratios (gated / plain of the same round: the two
trials of a round run back to back, so they share the machine's load, which the medians of the
two columns do not). Also, in this process and without the noise of a shared
machine, what the two gates cost by themselves (`gate_cost_ns`): the in gate and the out gate of
the gated configuration on N_FRAMES routed frames, best of 5, minus an empty loop.
"""

from __future__ import annotations

import statistics
import time

from bench import measure
from bench.measure import Path, log
from bench.routers import STREAMS_OFF, free_udp_port, gcsd_config, start_gcsd

RATE = 15000
TRIAL_S, QUICK_TRIAL_S = 6.0, 2.0
ROUNDS, QUICK_ROUNDS = 7, 2
GATE_A = ', filter: {in: {block_msgids: [PARAM_VALUE, SERIAL_CONTROL], block_src_sys: [99]}}'
GATE_B = (', filter: {out: {allow_src_sys: [1, 200, 250], block_msgids: [ATTITUDE_QUATERNION]}}, '
          'rate_limits: {ATTITUDE: 10, GLOBAL_POSITION_INT: 5, VFR_HUD: 4}')


def _path(runner, gated: bool) -> Path:
    s, r = runner.peers()
    port_a, port_b = free_udp_port(), free_udp_port()
    cfg = gcsd_config(runner.workdir, [
        f'{{name: a, type: udp-server, address: "127.0.0.1:{port_a}", streams: {STREAMS_OFF}{GATE_A if gated else ""}}}',
        f'{{name: b, type: udp-server, address: "127.0.0.1:{port_b}", streams: {STREAMS_OFF}{GATE_B if gated else ""}}}',
    ], extra="vehicle: {sysid: 1}")
    router = start_gcsd(runner.workdir, cfg, None, runner.gcsd_env)
    s.call("dest", ("127.0.0.1", port_a))
    r.call("peer", ("127.0.0.1", port_b), False)
    path = Path("gcsd-gated" if gated else "gcsd-plain", s, r, runner.seqs, router,
                {"router-in": port_a, "router-b": port_b, "receiver": r.port},
                idle_threshold_pct=runner.a.idle_threshold, idle_wait_s=runner.a.idle_wait)
    measure.wait_path_ready(path)
    return path


def measure_gates(runner) -> dict:
    quick = runner.a.quick
    us: dict[str, list[float]] = {"plain": [], "gated": []}
    lost: dict[str, int] = {"plain": 0, "gated": 0}
    others: list[float] = []
    for _ in range(QUICK_ROUNDS if quick else ROUNDS):
        for kind in ("plain", "gated"):
            path = _path(runner, kind == "gated")
            try:
                t = measure.run_trial_retrying(path, RATE, QUICK_TRIAL_S if quick else TRIAL_S)
            finally:
                path.router.stop()
            log(f"  [companion {kind}] {t.line()}")
            if t.received:
                us[kind].append(t.cpu_pct["router"] / 100 * (t.offered / RATE) / t.received * 1e6)
            lost[kind] += t.lost
            others.append(t.other_cpu_pct)
    plain = statistics.median(us["plain"]) if us["plain"] else None
    gated = statistics.median(us["gated"]) if us["gated"] else None
    ratios = [g / p for p, g in zip(us["plain"], us["gated"])]
    return {"rate": RATE, "gate_ns": gate_cost_ns(), "us_per_packet": us, "plain_us": plain, "gated_us": gated,
            "ratio": statistics.median(ratios) if ratios else None, "ratios": ratios, "lost": lost,
            "other_cpu_max_pct": max(others, default=0.0)}


def gate_cost_ns() -> float:
    """ns per frame of InGate.allow + OutGate.allow (the gated configuration, a frame that passes)."""
    from bench.frames import FrameFactory  # the routed frame, as the sender sends it
    from gcsd.config import parse_config
    from gcsd.routing.filters import gates
    from gcsd.wire.codec import FrameParser

    cfg = parse_config(f"channels:\n  - {{name: a, type: udp-server, address: '127.0.0.1:0'{GATE_A}}}\n"
                       f"  - {{name: b, type: udp-server, address: '127.0.0.1:0'{GATE_B}}}\n")
    inbound, _ = gates(cfg.channels[0])
    _, outbound = gates(cfg.channels[1])
    frame = FrameParser().feed(FrameFactory().frame(1))[0]
    raw, clock = frame.raw, time.monotonic
    n = 200_000

    def gated() -> float:
        start = time.perf_counter()
        for _ in range(n):
            inbound.allow(frame)
            outbound.allow(raw, clock)
        return time.perf_counter() - start

    def empty() -> float:
        start = time.perf_counter()
        for _ in range(n):
            pass
        return time.perf_counter() - start

    return (min(gated() for _ in range(5)) - min(empty() for _ in range(5))) / n * 1e9


def table(res: dict) -> str:
    if res.get("plain_us") is None or res.get("gated_us") is None:
        return "Companion filters and rate caps: no figure (no trial got through)"
    ok = "yes" if res["ratio"] <= 1.10 else "NO"
    rounds = ", ".join(f"{p:.1f}/{g:.1f} ({g / p:.2f})"
                       for p, g in zip(res["us_per_packet"]["plain"], res["us_per_packet"]["gated"]))
    return "\n".join([
        f"Companion filters and rate caps (bench/companion.py): CPU per routed packet at {res['rate']} pkt/s",
        (f"  without: {res['plain_us']:.1f} us; with filters on both channels and caps: {res['gated_us']:.1f} us "
         f"(medians); median of the rounds' ratios {res['ratio']:.3f} (SPEC <= 1.10: {ok})"),
        (f"  rounds (plain/gated us): {rounds}; packets lost: {res['lost']}; "
         f"max CPU of other processes during a trial: {res['other_cpu_max_pct']:.0f} % of one core"),
        f"  the two gates alone, in process: {res['gate_ns']:.0f} ns per frame",
    ])
