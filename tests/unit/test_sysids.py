"""SYSID_THISMAV across a swarm (issue 17, item 9): the pure rules of params/sysids.py."""

from __future__ import annotations

import pytest

from gcsd.vehicle.params.sysids import clash, start_sysids


def test_saved_sysids_that_are_distinct_are_kept_a_swap_included():
    assert start_sysids([1, 2, 3], [1, 2, 3]) == [1, 2, 3]
    assert start_sysids([1, 2, 3], [7, 2, 3]) == [7, 2, 3]
    assert start_sysids([1, 2, 3], [2, 1, 3]) == [2, 1, 3]


def test_a_saved_sysid_another_vehicle_has_falls_back_to_the_configured_one():
    assert start_sysids([1, 2, 3], [2, 2, 3]) == [1, 2, 3]
    assert start_sysids([1, 2, 3], [9, 9, 3]) == [1, 2, 3], "both wanted 9: neither gets it"


def test_fallbacks_cascade_until_no_two_are_the_same():
    # vehicle 1 falls back to 1, which vehicle 3 wanted: vehicle 3 falls back to 3
    assert start_sysids([1, 2, 3], [2, 2, 1]) == [1, 2, 3]


@pytest.mark.parametrize("bad", [0, 256, -1, 2.5, 1e9])
def test_a_saved_value_that_is_not_a_system_id_falls_back(bad):
    assert start_sysids([4], [bad]) == [4]


def test_a_sysid_another_vehicle_has_now_or_at_its_next_start_is_refused():
    current, pending = [1, 2, 3], [1, 2, 5]
    assert clash(0, 2, current, pending) == "SYSID_THISMAV 2 refused: another vehicle's sysid"
    assert clash(0, 5, current, pending) is not None, "vehicle 3 takes 5 at its next start"
    assert clash(0, 3, current, pending) is not None, "and has 3 until then"
    assert clash(0, 7, current, pending) is None
    assert clash(0, 1, current, pending) is None, "its own sysid again is no clash"
