"""Issue 17 item 11: two gcsd instances bridged both ways (two links between them) do not
circulate a broadcast: a loop dies out by default (dedup.py, `loop_dropped`).

A serves a ground station and reaches B over two udp-client links; B serves a second ground
station. A STATUSTEXT from the first station is a broadcast: A forwards it on both links, B
forwards each copy to the other link and to its station, and on 21d5d2b every copy came back
to A and went round again (33 000 returns in 5 s). Now each daemon drops a frame it has
already forwarded: the far station gets it once (the positive control), its sender never.
"""

from __future__ import annotations

import time

from .helpers import M, pump, udp_channel, udp_url, wait_for

A_SYSID, B_SYSID = 10, 20


def routes(d) -> set[tuple[int, str]]:
    return {(r["sysid"], r["channel"]) for r in d.status()["routes"]}


def test_a_broadcast_between_two_instances_bridged_both_ways_is_delivered_once_and_dies(daemon, client, tmp_path):
    b = daemon({"state_dir": str(tmp_path / "b"), "vehicle": {"sysid": B_SYSID},
                "channels": [udp_channel("gcs"), udp_channel("in1"), udp_channel("in2")]})
    a = daemon({"state_dir": str(tmp_path / "a"), "vehicle": {"sysid": A_SYSID},
                "channels": [udp_channel("gcs"),
                             {"name": "link1", "type": "udp-client", "address": f"127.0.0.1:{b.port('in1')}"},
                             {"name": "link2", "type": "udp-client", "address": f"127.0.0.1:{b.port('in2')}"}]})
    near, far = client(udp_url(a.port("gcs")), 255, 190), client(udp_url(b.port("gcs")), 254, 190)
    wanted_a = {(B_SYSID, "link1"), (B_SYSID, "link2"), (255, "gcs")}
    wanted_b = {(A_SYSID, "in1"), (A_SYSID, "in2"), (254, "gcs")}
    deadline = time.monotonic() + 10.0
    while not (wanted_a <= routes(a) and wanted_b <= routes(b)) and time.monotonic() < deadline:
        near.heartbeat()
        far.heartbeat()
        pump([near, far], 0.2)
    assert wanted_a <= routes(a) and wanted_b <= routes(b), "both links carry both vehicles; both stations heard"

    text = M.MAVLink_statustext_message(M.MAV_SEVERITY_INFO, b"hello over the bridge")
    marks = near.mark(), far.mark()
    sent = near.send(text)
    wait_for(far, lambda r: r.raw == sent, 3.0, marks[1], others=[near])
    pump([near, far], 1.0)  # ample for thousands of rounds at loopback speed (a round takes ~0.2 ms)
    returned = [r.raw for r in near.since(marks[0])].count(sent)
    assert returned == 0, f"the broadcast came back to its sender {returned} times"
    assert [r.raw for r in far.since(marks[1])].count(sent) == 1, "delivered once (the positive control)"
    assert wait_for(near, lambda r: r.type == "HEARTBEAT" and r.src == (B_SYSID, 1), 2.0, near.mark()), \
        "the far vehicle is still heard through the bridge"
    # counted: the copies of the text, and the frames each vehicle sent down both links with the
    # same bytes (the same sequence numbers on both: a second path is a duplicate too)
    assert sum(c["loop_dropped"] for d in (a, b) for c in d.status()["channels"]) >= 2
