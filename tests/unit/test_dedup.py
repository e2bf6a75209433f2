"""RecentFrames (dedup.py): exact bytes remembered for exactly window_s, bounded, on a float clock.
Every test runs on both implementations (Python, and C when gcsd.wire._speedups is built);
tests/unit/test_speedups.py compares them on random sequences."""

from __future__ import annotations

import pytest

from gcsd.routing import dedup
from gcsd.routing.dedup import LOOP_WINDOW_S
from gcsd.wire import speedups

IMPLEMENTATIONS = [
    pytest.param(dedup.RecentFramesPython, id="python"),
    pytest.param(speedups.compiled.RecentFrames if speedups.compiled else None, id="c",
                 marks=pytest.mark.skipif(speedups.compiled is None, reason="gcsd.wire._speedups is not built")),
]
RecentFrames = dedup.RecentFrames


@pytest.fixture(autouse=True, params=IMPLEMENTATIONS)
def implementation(request, monkeypatch):
    monkeypatch.setitem(globals(), "RecentFrames", request.param)
    return request.param

A, B = b"\xfd\x01frame-a", b"\xfd\x01frame-b"


def test_remembered_bytes_are_seen_until_the_window_ends_and_not_after():
    recent = RecentFrames(0.5)
    assert not recent.seen(A, 10.0)
    recent.remember(A, 10.0)
    assert recent.seen(A, 10.0) and recent.seen(A, 10.499)
    assert not recent.seen(A, 10.5), "forgotten exactly window_s later"
    assert not recent.seen(B, 10.1), "other bytes were never remembered"


def test_seen_changes_nothing_so_a_frame_that_keeps_coming_back_still_expires():
    recent = RecentFrames(0.5)
    recent.remember(A, 0.0)
    for t in (0.1, 0.2, 0.3, 0.4):
        assert recent.seen(A, t)
    assert not recent.seen(A, 0.6)


def test_expired_entries_leave_memory_as_new_ones_arrive():
    recent = RecentFrames(1.0)
    for i in range(1000):
        recent.remember(b"%d" % i, i * 0.01)  # 10 s of frames at 100 /s
    assert len(recent) <= 114, "only the last second is held (and an eighth of one between sweeps)"
    assert recent.evicted == 0, "nothing was forgotten early"


def test_a_frame_remembered_again_after_expiry_gets_a_new_full_window():
    recent = RecentFrames(0.5)
    recent.remember(A, 0.0)
    recent.remember(A, 1.0)  # expired, then forwarded again
    recent.remember(B, 1.2)  # expiry runs: the old (0.0, A) entry must not delete the new one
    assert recent.seen(A, 1.4)
    assert not recent.seen(A, 1.5)


def test_the_bound_forgets_the_oldest_first_and_counts_it():
    recent = RecentFrames(10.0, max_frames=3)
    for i, key in enumerate((b"1", b"2", b"3", b"4")):
        recent.remember(key, float(i))
    assert len(recent) == 3 and recent.evicted == 1
    assert not recent.seen(b"1", 4.0) and recent.seen(b"2", 4.0) and recent.seen(b"4", 4.0)


def test_check_is_dedup_in_one_call():
    recent = RecentFrames(0.2)
    assert recent.check(A, 0.0) is False  # first time: remembered
    assert recent.check(A, 0.1) is True  # the duplicate
    assert recent.check(A, 0.25) is False  # after the window: a new frame again


@pytest.mark.parametrize(("window_s", "max_frames"), [(0.0, 10), (-1.0, 10), (1.0, 0)])
def test_a_window_or_bound_that_holds_nothing_is_refused(window_s, max_frames):
    with pytest.raises(ValueError):
        RecentFrames(window_s, max_frames)


def test_the_loop_window_is_shorter_than_a_heartbeat_period():
    assert 0 < LOOP_WINDOW_S < 1.0

