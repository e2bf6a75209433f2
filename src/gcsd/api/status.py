"""What `gcsd status` shows of a running daemon (control.py serves it, formats it as tables):
its channels (counters, packet rates over the last statistics interval, signing rejects by
reason), learned routes, vehicles, the exceptions caught per component (`errors`), the counted
events outside the channels (`counters`), the HTTP API's state, and what runs the packet path
(`runtime`: the event loop, and whether gcsd.wire._speedups is compiled in: speedups.py)."""

from __future__ import annotations

from gcsd import __version__
from gcsd.loop import loop_name
from gcsd.wire import speedups


def document(gcs) -> dict:
    now = gcs.clock.now()
    channels = []
    for ch in gcs.live.running():
        snap = ch.snapshot()
        rate_in, rate_out = gcs.rates.get(ch.name, (0.0, 0.0))
        address = f"{ch.local_address[0]}:{ch.local_address[1]}" if ch.local_address else (
            ch.config.device or (ch.config.mqtt.broker if ch.config.mqtt else ""))
        channels.append({
            "name": ch.name, "type": ch.config.type, "address": address, "rate_in": rate_in,
            "rate_out": rate_out, "signature_reject_reasons": dict(ch.signature_reject_reasons), **snap,
        })
    routes = [
        {"sysid": r.sysid, "compid": r.compid, "channel": gcs.channels[r.channel].name,
         "mavtype": r.mavtype, "age_s": now - r.last_seen_s}
        for r in gcs.router.table
    ]
    vehicles = [
        {"sysid": n.sysid, "compid": n.compid, "type": n.vehicle.name,
         "mode": n.vehicle.modes.get(n.state.mode, str(n.state.mode)), "armed": n.state.armed}
        for n in gcs.nodes
    ]
    return {"version": __version__, "uptime_s": now - gcs.started_s,
            "runtime": {"loop": loop_name(), "speedups": speedups.IMPLEMENTATION}, "channels": channels,
            "routes": routes, "vehicles": vehicles, "errors": gcs.errors.snapshot(),
            "counters": counters(gcs), "http": None if gcs.http is None else gcs.http.state()}


def counters(gcs) -> dict[str, int]:
    """Counted events outside the channels: routing's, and every vehicle's summed."""
    out = {"routes_not_learned": gcs.router.table.not_learned,
           "unknown_ids_dropped": gcs.router.unknown_dropped, "bad_crc_forwarded": gcs.bad_crc_forwarded}
    for node in gcs.nodes:
        for name, n in node.counters().items():
            out[name] = out.get(name, 0) + n
    return dict(sorted(out.items()))
