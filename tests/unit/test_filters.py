"""Channel filters and rate caps as pure functions of frames and a float `now`."""

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.config import parse_config
from gcsd.config.companion import FilterRules
from gcsd.routing.filters import FrameFilter, gates, header
from gcsd.routing.ratecap import MAX_SOURCES, RateCaps
from gcsd.wire.codec import Encoder

ATT = M.MAVLINK_MSG_ID_ATTITUDE
HB = M.MAVLINK_MSG_ID_HEARTBEAT


def attitude(sysid=1, compid=1, mavlink1=False) -> bytes:
    return Encoder(sysid, compid).encode(M.MAVLink_attitude_message(0, 0, 0, 0, 0, 0, 0), mavlink1)


@pytest.mark.parametrize("mavlink1", [False, True])
def test_header_reads_msgid_and_source_of_both_versions(mavlink1):
    assert header(attitude(7, 42, mavlink1)) == (ATT, 7, 42)


def test_an_allow_list_passes_only_what_it_names_and_a_block_list_drops_what_it_names():
    f = FrameFilter(FilterRules(allow_msgids=frozenset({ATT, HB}), block_src_sys=frozenset({9})))
    assert f.passes(ATT, 1, 1) and f.passes(HB, 255, 190)
    assert not f.passes(M.MAVLINK_MSG_ID_PARAM_VALUE, 1, 1)  # not allowed
    assert not f.passes(ATT, 9, 1)  # allowed id, blocked source
    assert not f.passes(ATT, 9, 1)  # the memoised answer is the same


def test_allow_and_block_on_components():
    f = FrameFilter(FilterRules(allow_src_comp=frozenset({1, 191}), block_src_comp=frozenset({191})))
    assert f.passes(ATT, 1, 1) and not f.passes(ATT, 1, 191) and not f.passes(ATT, 1, 2)


def test_a_channel_without_filter_or_caps_has_no_gates():
    assert gates(parse_config("channels: [{name: a, type: udp-server, address: '127.0.0.1:0'}]").channels[0]) == (
        None, None)


def test_the_out_gate_filters_then_caps():
    ch = parse_config("channels: [{name: a, type: udp-server, address: '127.0.0.1:0', "
                      "filter: {out: {block_src_sys: [9]}}, rate_limits: {ATTITUDE: 10}}]").channels[0]
    inbound, outbound = gates(ch)
    assert inbound is None
    assert not outbound.allow(attitude(9), lambda: 0.0) and outbound.filtered == 1
    assert outbound.allow(attitude(1), lambda: 0.0) and not outbound.allow(attitude(1), lambda: 0.05)
    assert outbound.allow(attitude(1, mavlink1=True), lambda: 0.5)  # MAVLink1, the same source and cap
    assert outbound.caps.limited == 1 and outbound.filtered == 1


def test_a_cap_passes_the_first_frame_and_then_one_per_period():
    caps = RateCaps({ATT: 10})
    passed = [t / 1000 for t in range(0, 1000, 20) if caps.allow(ATT, 1, 1, t / 1000)]  # 50 Hz in
    assert passed == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]
    assert caps.limited == 40


def test_a_cap_never_delays_the_frame_that_passes_is_the_one_at_hand():
    caps = RateCaps({ATT: 10})
    assert caps.allow(ATT, 1, 1, 5.0)
    assert not caps.allow(ATT, 1, 1, 5.05)
    assert caps.allow(ATT, 1, 1, 5.13)  # after a 130 ms gap the next frame goes at once


def test_jittered_arrivals_still_get_the_full_capped_rate():
    caps = RateCaps({ATT: 10})
    times = [i * 0.02 + (0.0015 if i % 3 else -0.0015) for i in range(1, 501)]  # 50 Hz, +-1.5 ms, 10 s
    passed = sum(caps.allow(ATT, 1, 1, t) for t in times)
    assert 99 <= passed <= 101


def test_caps_are_per_source_and_per_message():
    caps = RateCaps({ATT: 1})
    assert caps.allow(ATT, 1, 1, 0.0) and caps.allow(ATT, 2, 1, 0.0) and caps.allow(ATT, 1, 2, 0.0)
    assert caps.allow(HB, 1, 1, 0.0) and caps.allow(HB, 1, 1, 0.0)  # no cap on HEARTBEAT
    assert not caps.allow(ATT, 2, 1, 0.5)


def test_after_a_silence_no_burst_is_owed():
    caps = RateCaps({ATT: 10})
    assert caps.allow(ATT, 1, 1, 0.0)
    assert caps.allow(ATT, 1, 1, 10.0)
    assert not caps.allow(ATT, 1, 1, 10.01)  # the schedule restarted at 10.0, not 0.1


def test_the_source_table_is_bounded():
    caps = RateCaps({ATT: 1})
    for i in range(MAX_SOURCES + 10):
        assert caps.allow(ATT, i % 256, i // 256, 0.0)
