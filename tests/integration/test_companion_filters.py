"""Companion routing: per-channel filters and rate caps, on real sockets (SPEC.md "Companion routing").

A fake flight controller (sysid 7) on channel `fc`, and two ground stations side by side: one on
a channel with a filter or a cap, one on a plain channel. Each "nothing arrived" check has its
positive control in the same window: a frame sent through the same socket just after the one
that must not arrive, which does arrive (the daemon reads one socket in order and writes each
channel's frames in order), or the plain channel receiving what the filtered one must not.
"""

from __future__ import annotations

import time

from .helpers import VEHICLE, M, from_vehicle, udp_channel, udp_url, wait_for

FC = (7, 1)


def _attitude(t_ms: int):
    return M.MAVLink_attitude_message(t_ms, 0.1, 0.2, 0.3, 0, 0, 0)


def _status():
    return M.MAVLink_sys_status_message(0, 0, 0, 500, 12000, -1, -1, 0, 0, 0, 0, 0, 0)


def _start(daemon, client, **filtered):
    d = daemon({"channels": [udp_channel("fc"), udp_channel("filtered", **filtered), udp_channel("open")]})
    fc = client(udp_url(d.port("fc")), *FC)
    gf = client(udp_url(d.port("filtered")), 255, 190)
    go = client(udp_url(d.port("open")), 254, 190)
    everyone = [fc, gf, go]
    fc.heartbeat(M.MAV_TYPE_QUADROTOR)
    gf.heartbeat()
    go.heartbeat()
    for c in everyone:
        assert wait_for(c, from_vehicle, others=everyone), "nothing from the daemon's vehicle"
    return d, fc, gf, go, everyone


def test_a_filtered_and_an_unfiltered_channel_side_by_side(daemon, client):
    d, fc, gf, go, everyone = _start(daemon, client, filter={"out": {"block_msgids": ["ATTITUDE"]}})
    marks = {c: c.mark() for c in everyone}
    att = fc.send(_attitude(1))
    status = fc.send(_status())  # control: the next frame through the same socket
    for c in (gf, go):
        assert wait_for(c, lambda r: r.raw == status, since=marks[c], others=everyone)
    assert [r.raw for r in go.since(marks[go]) if r.raw == att] == [att]  # the plain channel: forwarded
    assert [r for r in gf.since(marks[gf]) if r.raw == att] == []  # the filtered one: not
    # our own ATTITUDE stream is held back too (filter.out is everything written to the channel)
    assert wait_for(go, lambda r: r.type == "ATTITUDE" and r.src == VEHICLE, since=marks[go], others=everyone)
    assert wait_for(gf, lambda r: r.type == "GLOBAL_POSITION_INT" and r.src == VEHICLE, since=marks[gf],
                    others=everyone)
    assert [r for r in gf.since(marks[gf], "ATTITUDE")] == []
    counters = {c["name"]: c for c in d.status()["channels"]}
    assert counters["filtered"]["filtered_out"] >= 2 and counters["open"]["filtered_out"] == 0


def test_an_in_filter_keeps_a_frame_from_routing_and_local_handling(daemon, client):
    d, fc, gf, go, everyone = _start(daemon, client, filter={"in": {"block_msgids": ["PARAM_SET"]}})
    marks = {c: c.mark() for c in everyone}
    blocked = gf.send(M.MAVLink_param_set_message(*VEHICLE, b"BATT_ARM_VOLT", 42.5, M.MAV_PARAM_TYPE_REAL32))
    gf.send(M.MAVLink_param_request_read_message(*VEHICLE, b"BATT_ARM_VOLT", -1))  # control, same socket
    answer = wait_for(gf, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == "BATT_ARM_VOLT",
                      since=marks[gf], others=everyone)
    assert answer is not None and answer.msg.param_value != 42.5
    assert [r for r in fc.since(marks[fc]) if r.raw == blocked] == []  # not forwarded either
    # the same PARAM_SET from the plain channel is handled: the positive control of the filter itself
    go.send(M.MAVLink_param_set_message(*VEHICLE, b"BATT_ARM_VOLT", 42.5, M.MAV_PARAM_TYPE_REAL32))
    assert wait_for(go, lambda r: r.type == "PARAM_VALUE" and r.msg.param_value == 42.5, others=everyone)
    assert {c["name"]: c["filtered_in"] for c in d.status()["channels"]}["filtered"] == 1


def test_a_capped_channel_gets_the_cap_while_another_gets_the_full_rate(daemon, client):
    d, fc, gf, go, everyone = _start(daemon, client, rate_limits={"ATTITUDE": 10})
    marks = {c: c.mark() for c in everyone}
    sent = []
    start = time.monotonic()
    period_s, duration_s = 0.01, 2.0  # 100 Hz for 2 s
    for i in range(int(duration_s / period_s)):
        delay = start + i * period_s - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        sent.append(fc.send(_attitude(i)))
        for c in (gf, go):
            c.read_available()
    last = fc.send(_status())  # control: both channels have everything once they have this
    for c in (gf, go):
        assert wait_for(c, lambda r: r.raw == last, since=marks[c], others=everyone)
    sent_set = set(sent)
    full = [r for r in go.since(marks[go]) if r.raw in sent_set]
    capped = [r for r in gf.since(marks[gf]) if r.raw in sent_set]
    elapsed = time.monotonic() - start
    assert len(full) == len(sent)
    assert 0.8 * 10 * duration_s <= len(capped) <= 10 * elapsed + 1, (len(capped), elapsed)
    # the daemon's own ATTITUDE (sysid 1) is capped separately: the cap is per source
    counters = {c["name"]: c for c in d.status()["channels"]}
    assert counters["filtered"]["rate_limited"] >= len(sent) - len(capped)
    assert counters["open"]["rate_limited"] == 0
