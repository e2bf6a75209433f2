"""The RFC 6298 round-trip estimator, with plain float times (no clock, no sleeps)."""

from __future__ import annotations

import pytest

from gcsd.vehicle.mission.rtt import GRANULARITY_S, INITIAL_RTO_S, MIN_RTO_S, RttEstimator, RttTable


def test_before_any_sample_the_timeout_is_the_initial_value():
    est = RttEstimator(initial_s=1.0)
    assert est.rto_s == 1.0 and est.srtt_s is None
    assert RttEstimator(max_s=1.0).rto_s == INITIAL_RTO_S == 0.25
    assert RttEstimator(max_s=0.1).rto_s == 0.1  # never above the ceiling


def test_the_first_sample_sets_srtt_and_half_of_it_as_rttvar():
    est = RttEstimator(initial_s=1.0)
    est.sample(0.2)
    assert est.srtt_s == pytest.approx(0.2)
    assert est.rttvar_s == pytest.approx(0.1)
    assert est.rto_s == pytest.approx(0.2 + 4 * 0.1)


def test_later_samples_smooth_with_alpha_one_eighth_and_beta_one_quarter():
    est = RttEstimator(initial_s=5.0)
    est.sample(0.2)
    est.sample(0.6)
    assert est.rttvar_s == pytest.approx(0.75 * 0.1 + 0.25 * 0.4)
    assert est.srtt_s == pytest.approx(0.875 * 0.2 + 0.125 * 0.6)
    assert est.rto_s == pytest.approx(est.srtt_s + 4 * est.rttvar_s)


def test_a_steady_fast_link_settles_at_the_floor():
    est = RttEstimator(initial_s=1.0)
    for _ in range(50):
        est.sample(0.001)
    assert est.rto_s == pytest.approx(MIN_RTO_S)
    assert est.base_rto_s >= est.srtt_s + GRANULARITY_S


def test_a_slow_link_is_clamped_to_the_ceiling():
    est = RttEstimator(initial_s=1.0)
    est.sample(4.0)
    assert est.rto_s == 1.0


def test_a_separate_ceiling_above_the_initial_value():
    est = RttEstimator(initial_s=1.0, max_s=3.0)
    est.sample(1.0)
    assert est.rto_s == pytest.approx(3.0)


def test_timeouts_double_the_rto_at_most_twice_and_a_sample_clears_the_backoff():
    est = RttEstimator(initial_s=1.0)
    est.sample(0.05)  # RTO 0.05 + 0.1 = 0.15
    seen = []
    for _ in range(4):
        est.timed_out()
        seen.append(round(est.rto_s, 6))
    assert seen == [0.3, 0.6, 0.6, 0.6]
    est.sample(0.05)
    assert est.backoff == 0
    assert est.rto_s < 0.15


def test_the_backoff_never_goes_beyond_the_ceiling():
    est = RttEstimator(initial_s=1.0)
    est.sample(0.2)  # RTO 0.6
    est.timed_out()
    assert est.rto_s == 1.0
    fresh = RttEstimator(initial_s=1.0)
    fresh.timed_out()
    assert fresh.rto_s == 1.0


def test_the_backlog_of_the_link_is_added_beyond_the_ceiling():
    """A 57 600 baud radio (5 760 bytes/s) with 576 bytes queued ahead of the request: +0.1 s."""
    est = RttEstimator(initial_s=1.0)
    assert est.timeout_s(queued_s=576 / 5760) == pytest.approx(1.1)
    est.sample(0.02)
    assert est.timeout_s(queued_s=0.1) == pytest.approx(est.rto_s + 0.1)
    assert est.timeout_s(queued_s=-1.0) == est.rto_s


def test_a_negative_sample_counts_as_zero():
    est = RttEstimator(initial_s=1.0)
    est.sample(-0.5)
    assert est.srtt_s == 0.0 and est.rto_s == MIN_RTO_S


def test_the_table_keeps_one_estimator_per_peer_and_forgets_the_least_recently_used():
    table = RttTable(initial_s=1.0, max_peers=2)
    a = table.get(("gcs", 255, 190))
    a.sample(0.01)
    assert table.get(("gcs", 255, 190)) is a
    table.get(("gcs", 250, 1))
    table.get(("gcs", 255, 190))  # a is now the most recent
    table.get(("radio", 255, 190))  # evicts (gcs, 250, 1)
    assert len(table) == 2
    assert table.get(("gcs", 255, 190)) is a
    assert table.get(("gcs", 250, 1)).srtt_s is None
