"""ErrorCounts.guard: the one error boundary's block form (boundary.py)."""

from __future__ import annotations

import asyncio

import pytest

from gcsd.boundary import LOG_INTERVAL_S, ErrorCounts


def test_guard_counts_and_swallows_an_exception_and_the_code_after_it_runs():
    errors = ErrorCounts()
    after = []
    with errors.guard("stats", 1.0, channel="gcs"):
        raise ValueError("broken")
    after.append(True)
    with errors.guard("stats", 2.0):
        pass
    assert errors.snapshot() == {"stats": 1} and after == [True]


def test_guard_lets_cancellation_and_exit_through():
    errors = ErrorCounts()
    with pytest.raises(asyncio.CancelledError), errors.guard("task", 0.0):
        raise asyncio.CancelledError
    with pytest.raises(SystemExit), errors.guard("task", 0.0):
        raise SystemExit(1)
    assert errors.total() == 0


def test_guard_logs_the_traceback_at_most_once_per_interval_per_component(capsys):
    errors = ErrorCounts()
    for now in (0.0, 1.0, 2.0, LOG_INTERVAL_S + 0.5):
        with errors.guard("persist:mav.parm", now):
            raise OSError("disk gone")
    logged = capsys.readouterr()
    text = logged.out + logged.err
    assert errors.counts["persist:mav.parm"] == 4
    assert text.count("component_failed") == 2 and "OSError: disk gone" in text
