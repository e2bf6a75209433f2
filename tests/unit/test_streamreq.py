"""request_streams: which autopilots are asked for their streams, and when (fake clock)."""

from gcsd.routing.streamreq import SILENCE_S, StreamRequests

QUAD, ARDUPILOT, GCS, INVALID = 2, 3, 6, 8


def test_an_autopilot_is_asked_when_first_heard_and_not_again_while_it_talks():
    r = StreamRequests(4)
    assert r.heartbeat(1, 1, QUAD, ARDUPILOT, 0.0)
    assert not r.heartbeat(1, 1, QUAD, ARDUPILOT, 1.0)
    assert not r.heartbeat(1, 1, QUAD, ARDUPILOT, 1.0 + SILENCE_S)


def test_ground_stations_and_non_autopilots_are_never_asked():
    r = StreamRequests(4)
    assert not r.heartbeat(255, 190, GCS, INVALID, 0.0)
    assert not r.heartbeat(1, 100, 30, INVALID, 0.0)  # a camera
    assert not r.heartbeat(9, 1, GCS, ARDUPILOT, 0.0)


def test_a_heartbeat_back_after_five_seconds_of_silence_is_asked_again():
    r = StreamRequests(4)
    r.heartbeat(1, 1, QUAD, ARDUPILOT, 0.0)
    assert r.heartbeat(1, 1, QUAD, ARDUPILOT, SILENCE_S + 0.01)
    assert r.sent == 2


def test_system_time_going_back_is_a_reboot():
    r = StreamRequests(4)
    r.heartbeat(1, 1, QUAD, ARDUPILOT, 0.0)
    assert not r.system_time(1, 1, 10_000)
    assert not r.system_time(1, 1, 11_000)
    assert r.system_time(1, 1, 300)
    assert not r.system_time(7, 1, 5)  # not an autopilot we know
