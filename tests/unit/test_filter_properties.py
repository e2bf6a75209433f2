"""Properties of the channel gates, over generated rules and traffic (hypothesis): the memoised
filter answers as the rule says, whatever it saw before; a rate cap never lets more than one
frame per period through, plus the first."""

from hypothesis import given, settings
from hypothesis import strategies as st

from gcsd.config.companion import FilterRules
from gcsd.routing.filters import FrameFilter
from gcsd.routing.ratecap import SLACK_S, RateCaps

MSGIDS = st.sampled_from([0, 1, 24, 30, 33, 74, 76, 253, 12915])
BYTES = st.integers(0, 255)


def optional_sets(values):
    return st.none() | st.frozensets(values, max_size=4)


@st.composite
def rules(draw) -> FilterRules:
    return FilterRules(
        allow_msgids=draw(optional_sets(MSGIDS)), block_msgids=draw(st.frozensets(MSGIDS, max_size=4)),
        allow_src_sys=draw(optional_sets(BYTES)), block_src_sys=draw(st.frozensets(BYTES, max_size=4)),
        allow_src_comp=draw(optional_sets(BYTES)), block_src_comp=draw(st.frozensets(BYTES, max_size=4)))


def naive(r: FilterRules, msgid: int, sysid: int, compid: int) -> bool:
    def ok(value, allow, block):
        return (allow is None or value in allow) and value not in block
    return (ok(msgid, r.allow_msgids, r.block_msgids) and ok(sysid, r.allow_src_sys, r.block_src_sys)
            and ok(compid, r.allow_src_comp, r.block_src_comp))


@settings(max_examples=300)
@given(rules(), st.lists(st.tuples(MSGIDS, BYTES, BYTES), min_size=1, max_size=40))
def test_the_memoised_filter_answers_as_the_rule_says(rule, frames):
    f = FrameFilter(rule)
    for frame in frames + frames:  # the second time from the memo
        assert f.passes(*frame) == naive(rule, *frame)


@settings(max_examples=300)
@given(st.floats(0.5, 100.0), st.lists(st.floats(0.0, 0.2), min_size=1, max_size=300))
def test_a_cap_passes_at_most_one_frame_per_period_plus_the_first(hz, gaps):
    caps = RateCaps({30: hz})
    now, passed = 0.0, []
    for gap in gaps:
        now += gap
        if caps.allow(30, 1, 1, now):
            passed.append(now)
    period = 1.0 / hz
    assert passed  # the first frame always goes
    for k, t in enumerate(passed):
        assert t >= passed[0] + k * period - (k + 1) * SLACK_S
    assert caps.limited == len(gaps) - len(passed)
