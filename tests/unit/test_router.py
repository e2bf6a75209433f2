"""The routing decision, table-driven, against REFERENCE.md section 3.

World used by the table: we are (1, 1). Channel 0 has a GCS (255, 190); channel 1 has a second
GCS (254, 190); channel 2 has a camera (1, 100) of our own system; channel 3 has another
vehicle (7, 1). Every channel is active.
"""

from __future__ import annotations

import pytest

from gcsd.routing.router import ChannelPolicy, Decision, Router, RouteTable

HB, CMD, RADIO_STATUS, PARAM_SET = 0, 76, 109, 23
GCS1, GCS2, CAM, OTHER = (255, 190), (254, 190), (1, 100), (7, 1)
SEEN = {0: GCS1, 1: GCS2, 2: CAM, 3: OTHER}


def make_router(policies=None, nodes=SEEN) -> Router:
    router = Router({(1, 1)}, policies or [ChannelPolicy()] * 4)
    for ch, (s, c) in nodes.items():
        router.decide(ch, HB, s, c, -1, -1, now=0.0, active_channels={0, 1, 2, 3})
    return router


def decide(router, in_ch, src, msgid, ts, tc, known=True):
    return router.decide(in_ch, msgid, src[0], src[1], ts, tc, now=1.0, active_channels={0, 1, 2, 3}, known_message=known)


@pytest.mark.parametrize(
    "case, in_ch, src, msgid, ts, tc, expected",
    [
        ("addressed exactly to us: processed, not forwarded", 0, GCS1, CMD, 1, 1, Decision(True, ())),
        ("to our camera: forwarded to its channel only, not processed", 0, GCS1, CMD, 1, 100, Decision(False, (2,))),
        ("to our system, component 0: processed and copied to our components", 0, GCS1, CMD, 1, 0, Decision(True, (2,))),
        ("to our system, unknown component: processed locally (rule 1e)", 0, GCS1, CMD, 1, 55, Decision(True, ())),
        ("broadcast: processed and copied to every other channel with a route", 0, GCS1, CMD, 0, 0, Decision(True, (1, 2, 3))),
        ("no target field: like a broadcast", 2, CAM, 30, -1, -1, Decision(True, (0, 1, 3))),
        ("another system: forwarded where it was seen, not processed", 0, GCS1, CMD, 7, 1, Decision(False, (3,))),
        ("another system, any component: component is not checked", 0, GCS1, CMD, 7, 99, Decision(False, (3,))),
        ("unknown system: dropped", 0, GCS1, CMD, 77, 1, Decision(False, ())),
        ("reply to a GCS: back to that GCS's channel only", 2, CAM, CMD, 255, 190, Decision(False, (0,))),
        ("RADIO_STATUS: processed, never forwarded", 0, GCS1, RADIO_STATUS, -1, -1, Decision(True, ())),
        ("heartbeat: to every other active channel", 0, GCS1, HB, -1, -1, Decision(True, (1, 2, 3))),
        ("unknown message id: forwarded as broadcast, not processed", 0, GCS1, 42424, -1, -1, Decision(False, (1, 2, 3))),
    ],
)
def test_routing_rules(case, in_ch, src, msgid, ts, tc, expected):
    router = make_router()
    assert decide(router, in_ch, src, msgid, ts, tc, known=msgid != 42424) == expected, case


def test_router_never_echoes_to_origin_channel():
    # the target system was seen only on the ingress channel
    router = make_router()
    assert decide(router, 3, OTHER, CMD, 7, 1) == Decision(False, ())
    assert 0 not in decide(router, 0, GCS1, CMD, 0, 0).out_channels
    assert 0 not in decide(router, 0, GCS1, HB, -1, -1).out_channels


def test_frames_from_our_own_component_are_ignored_and_not_learned():
    router = make_router()
    assert decide(router, 0, (1, 1), CMD, 0, 0) == Decision(False, ())
    assert not router.table.has(1, 1, 0)


def test_sysid_zero_and_our_sysid_with_compid_zero_are_not_learned():
    router = make_router()
    decide(router, 1, (0, 5), CMD, 0, 0)
    decide(router, 1, (1, 0), CMD, 0, 0)
    assert not router.table.has(0, 5, 1)
    assert not router.table.has(1, 0, 1)


def test_same_node_on_two_channels_gives_two_routes():
    router = make_router()
    decide(router, 1, GCS1, HB, -1, -1)
    assert router.table.has(*GCS1, 0) and router.table.has(*GCS1, 1)
    assert decide(router, 2, CAM, CMD, 255, 190).out_channels == (0, 1)


def test_broadcast_only_reaches_channels_with_routes():
    router = make_router(nodes={0: GCS1, 2: CAM})
    assert decide(router, 0, GCS1, CMD, 0, 0).out_channels == (2,)


def test_heartbeat_goes_to_active_channels_without_routes_too():
    router = make_router(nodes={0: GCS1})
    assert decide(router, 0, GCS1, HB, -1, -1).out_channels == (1, 2, 3)


def test_heartbeat_is_not_sent_where_the_same_node_is_already_seen():
    router = make_router()
    decide(router, 1, GCS1, HB, -1, -1)  # GCS1 now also on channel 1
    assert decide(router, 0, GCS1, HB, -1, -1).out_channels == (2, 3)


def test_heartbeat_only_to_active_channels():
    router = Router({(1, 1)}, [ChannelPolicy()] * 4)
    d = router.decide(0, HB, 255, 190, -1, -1, now=0.0, active_channels={0, 2})
    assert d.out_channels == (2,)


PRIVATE_2 = [ChannelPolicy(), ChannelPolicy(), ChannelPolicy(private=True), ChannelPolicy()]
NO_FORWARD_2 = [ChannelPolicy(), ChannelPolicy(), ChannelPolicy(no_forward=True), ChannelPolicy()]


def test_private_channel_gets_no_forwarded_broadcasts_or_heartbeats():
    router = make_router(PRIVATE_2)
    assert 2 not in decide(router, 0, GCS1, CMD, 0, 0).out_channels
    assert 2 not in decide(router, 0, GCS1, HB, -1, -1).out_channels


def test_private_channel_gets_exactly_addressed_frames():
    router = make_router(PRIVATE_2)
    assert decide(router, 0, GCS1, CMD, 1, 100) == Decision(False, (2,))
    # a frame for the system only (component 0) is not exact: not for the private channel
    assert 2 not in decide(router, 0, GCS1, CMD, 1, 0).out_channels


def test_nothing_from_a_private_channel_is_forwarded():
    router = make_router(PRIVATE_2)
    assert decide(router, 2, CAM, CMD, 255, 190) == Decision(False, ())
    assert decide(router, 2, CAM, CMD, 0, 0) == Decision(True, ())
    assert decide(router, 2, CAM, HB, -1, -1) == Decision(True, ())
    assert decide(router, 2, CAM, CMD, 1, 1) == Decision(True, ())


def test_no_forward_channel_gets_nothing_forwarded_even_exactly_addressed():
    router = make_router(NO_FORWARD_2)
    assert decide(router, 0, GCS1, CMD, 1, 100) == Decision(True, ())
    assert 2 not in decide(router, 0, GCS1, HB, -1, -1).out_channels
    assert decide(router, 2, CAM, CMD, 255, 190) == Decision(False, ())


def test_swarm_processes_frames_for_each_local_sysid():
    router = Router({(1, 1), (2, 1), (3, 1)}, [ChannelPolicy()] * 2)
    router.decide(0, HB, 255, 190, -1, -1, now=0.0, active_channels={0})
    assert router.decide(0, CMD, 255, 190, 2, 1, now=0.0) == Decision(True, ())
    assert router.decide(0, CMD, 255, 190, 3, 0, now=0.0) == Decision(True, ())
    assert router.decide(0, CMD, 255, 190, 4, 1, now=0.0) == Decision(False, ())


# --- the table ---------------------------------------------------------------------------
def test_route_table_holds_twenty_routes():
    table = RouteTable()
    for sysid in range(1, 26):
        table.learn(sysid, 1, 0, now=0.0)
    assert len(table) == 20
    assert table.not_learned == 5
    assert not table.has(21, 1, 0)


def test_full_table_replaces_a_route_silent_for_30_s():
    table = RouteTable()
    for sysid in range(1, 21):
        table.learn(sysid, 1, 0, now=0.0)
    for sysid in range(2, 21):
        table.learn(sysid, 1, 0, now=29.0)  # all but sysid 1 keep talking
    table.learn(99, 1, 0, now=29.5)
    assert not table.has(99, 1, 0), "nothing is stale yet"
    table.learn(99, 1, 0, now=30.5)
    assert table.has(99, 1, 0)
    assert not table.has(1, 1, 0), "the silent route was replaced"
    assert len(table) == 20


def test_full_table_keeps_live_routes():
    table = RouteTable()
    for sysid in range(1, 21):
        table.learn(sysid, 1, 0, now=100.0)
    table.learn(99, 1, 0, now=110.0)
    assert not table.has(99, 1, 0)
    assert all(table.has(s, 1, 0) for s in range(1, 21))


def test_router_forwards_to_a_node_learned_when_a_silent_route_was_replaced():
    """The table full of 20 routes (SEEN's 4 + 16 on channel 3): a 21st node on channel 1 is not
    learned while all are fresh, so frames for it are dropped; once the GCS on channel 1 has been
    silent 30 s the newcomer takes its place and frames for it go to channel 1."""
    router = make_router()
    for i in range(16):
        router.decide(3, HB, 100 + i, 1, -1, -1, now=0.0, active_channels={0, 1, 2, 3})
    assert len(router.table) == 20
    channels = {0, 1, 2, 3}

    def keep_talking(now: float) -> None:  # everyone but GCS2 on channel 1
        for ch, (s, c) in {0: GCS1, 2: CAM, 3: OTHER}.items():
            router.decide(ch, HB, s, c, -1, -1, now=now, active_channels=channels)
        for i in range(16):
            router.decide(3, HB, 100 + i, 1, -1, -1, now=now, active_channels=channels)

    keep_talking(20.0)
    router.decide(1, HB, 42, 1, -1, -1, now=20.0, active_channels=channels)
    assert router.decide(0, CMD, *GCS1, 42, 1, now=20.0, active_channels=channels) == Decision(False, ())
    assert router.decide(0, CMD, *GCS1, 254, 190, now=20.0, active_channels=channels) == Decision(False, (1,))
    keep_talking(30.5)
    router.decide(1, HB, 42, 1, -1, -1, now=30.5, active_channels=channels)
    assert router.decide(0, CMD, *GCS1, 42, 1, now=30.5, active_channels=channels) == Decision(False, (1,))
    assert not router.table.has(*GCS2, 1), "the silent ground station's route was the one replaced"


def test_route_remembers_mavtype_from_first_heartbeat():
    table = RouteTable()
    table.learn(5, 1, 0, now=0.0)
    table.learn(5, 1, 0, now=1.0, mavtype=2)
    table.learn(5, 1, 0, now=2.0, mavtype=6)
    assert [r.mavtype for r in table] == [2]


def test_unknown_message_from_an_unseen_source_is_dropped_and_not_learned():
    router = make_router()
    assert decide(router, 0, (42, 7), 42424, -1, -1, known=False) == Decision(False, ())
    assert not router.table.has(42, 7, 0)
    assert router.unknown_dropped == 1


def test_unknown_message_from_a_private_channel_is_not_forwarded():
    router = make_router(PRIVATE_2)
    assert decide(router, 2, CAM, 42424, -1, -1, known=False) == Decision(False, ())


# --- groups: redundant links to the same systems (SPEC.md "Companion routing") ---------------------
# channel 0: a GCS; channels 1 and 2: radio and LTE to one flight controller (7, 1), group "fc";
# channel 3: a second GCS.

def grouped_router(fc_seen_on=(1,)) -> Router:
    policies = [ChannelPolicy(), ChannelPolicy(group="fc"), ChannelPolicy(group="fc"), ChannelPolicy()]
    router = Router({(1, 1)}, policies)
    router.decide(0, HB, *GCS1, -1, -1, now=0.0, active_channels={0, 1, 2, 3})
    router.decide(3, HB, *GCS2, -1, -1, now=0.0, active_channels={0, 1, 2, 3})
    for ch in fc_seen_on:
        router.decide(ch, HB, *OTHER, -1, -1, now=0.0, active_channels={0, 1, 2, 3})
    return router


def test_a_route_learned_on_one_link_of_a_group_is_a_route_on_every_link():
    router = grouped_router(fc_seen_on=(1,))  # heard on the radio only
    assert decide(router, 0, GCS1, CMD, 7, 1) == Decision(False, (1, 2))


def test_nothing_from_a_group_goes_back_out_on_the_group():
    router = grouped_router(fc_seen_on=(1, 2))
    assert sorted(decide(router, 1, OTHER, CMD, 0, 0).out_channels) == [0, 3]  # broadcast from the FC
    assert sorted(decide(router, 2, OTHER, HB, -1, -1).out_channels) == [0, 3]
    assert decide(router, 1, OTHER, CMD, 255, 190) == Decision(False, (0,))  # reply to one GCS


def test_a_broadcast_from_a_gcs_goes_to_every_link_of_the_group_once():
    router = grouped_router(fc_seen_on=(2,))
    got = decide(router, 0, GCS1, CMD, 0, 0)
    assert got.process_locally and sorted(got.out_channels) == [1, 2, 3]


def _linear_out(router: Router, in_channel: int, ts: int, tc: int) -> set[int]:
    """The forwarding rule as a walk over every route (the table before it was indexed)."""
    out = set()
    for route in router.table:
        ch, policy = route.channel, router.policies[route.channel]
        if ch == in_channel or policy.no_forward:
            continue
        if policy.private:
            if (ts, tc) == (route.sysid, route.compid):
                out.add(ch)
            continue
        if ts <= 0 or (ts == route.sysid and (tc <= 0 or tc == route.compid or ts not in router.local_sysids)):
            out.add(ch)
    return out


def test_the_indexed_table_forwards_as_a_walk_over_every_route_would():
    import random

    rng = random.Random(7)
    policies = [ChannelPolicy(), ChannelPolicy(), ChannelPolicy(private=True), ChannelPolicy(no_forward=True),
                ChannelPolicy()]
    router = Router({(1, 1)}, policies, RouteTable(300))
    for _ in range(400):  # sources come and go; some are relearned on other channels
        router.table.learn(rng.randint(2, 60), rng.choice((0, 1, 100, 190)), rng.randrange(5), 0.0)
    assert len(router.table) == sum(len(router.table.routes_of(s)) for s in range(256))
    for _ in range(3000):
        in_channel = rng.randrange(5)
        ts, tc = rng.choice((-1, 0, 1, rng.randint(2, 70))), rng.choice((-1, 0, 1, 100, 190))
        if in_channel in (2, 3) or (ts > 0 and tc > 0 and (ts, tc) in router.local):
            continue
        decision = router.decide(in_channel, CMD, 250, 190, ts, tc, 1.0)
        assert set(decision.out_channels) == _linear_out(router, in_channel, ts, tc), (in_channel, ts, tc)
