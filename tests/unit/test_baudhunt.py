"""The baud list of a serial channel: tried in turn until a good frame, then kept (fake clock)."""

from gcsd.links.baudhunt import PROBE_S, BaudHunt


def test_bauds_are_tried_in_turn_until_a_good_frame():
    hunt = BaudHunt((921600, 115200, 57600))
    assert hunt.opening(0.0) == 921600
    assert not hunt.expired(PROBE_S - 0.01)
    assert hunt.expired(PROBE_S)
    assert hunt.opening(PROBE_S) == 115200
    assert hunt.expired(2 * PROBE_S)
    assert hunt.opening(2 * PROBE_S) == 57600
    assert hunt.expired(3 * PROBE_S)
    assert hunt.opening(3 * PROBE_S) == 921600  # round and round


def test_a_good_frame_locks_the_baud():
    hunt = BaudHunt((921600, 57600))
    hunt.opening(0.0)
    assert hunt.expired(PROBE_S)
    assert hunt.opening(PROBE_S) == 57600
    hunt.heard()
    assert not hunt.expired(100.0)


def test_a_device_that_comes_back_is_opened_at_the_baud_that_worked_first():
    hunt = BaudHunt((921600, 57600))
    hunt.opening(0.0)
    hunt.expired(PROBE_S)
    hunt.opening(PROBE_S)
    hunt.heard()
    hunt.closed()  # unplugged
    assert hunt.opening(50.0) == 57600
    assert hunt.expired(50.0 + PROBE_S)  # and probing resumes if it hears nothing there
    assert hunt.opening(52.0) == 921600


def test_a_single_baud_never_expires():
    hunt = BaudHunt((115200,))
    assert hunt.opening(0.0) == 115200
    assert not hunt.expired(1000.0)
