"""statelock.py: one holder per state directory, released with the descriptor."""

from __future__ import annotations

import os

import pytest

from gcsd.daemon.statelock import LOCK_NAME, StateDirBusy, acquire


def test_a_second_holder_is_refused_with_the_first_ones_pid_until_it_releases(tmp_path):
    first = acquire(tmp_path)
    assert (tmp_path / LOCK_NAME).read_text() == f"{os.getpid()}\n"
    with pytest.raises(StateDirBusy, match=rf"in use by another gcsd \(pid {os.getpid()}\)"):
        acquire(tmp_path)  # flock is per open file: the same process is refused too
    first.release()
    second = acquire(tmp_path)  # positive control: free again once released
    second.release()
    second.release()  # idempotent


def test_a_missing_state_dir_is_an_os_error_not_a_lock(tmp_path):
    with pytest.raises(FileNotFoundError):
        acquire(tmp_path / "missing")
