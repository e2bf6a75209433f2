"""Missions, fence and rally through the real daemon: pymavlink ground stations on loopback UDP.

Round trips of each plan type, the plans surviving a restart, a bad plan file kept aside,
ownership between two ground stations, MAVLink1 and legacy messages, the current item, and a
500-item mission through a proxy that loses 20 % of the datagrams in each direction (the
re-requests in real time). The timers themselves (back-off to mission.retry_ms, the 8 s abort,
streams slowed while items are requested) are pinned with a float clock in
tests/unit/test_mission_transfer.py and tests/unit/test_mission_service.py.
"""

from __future__ import annotations

import time
from dataclasses import replace

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission import MissionItem

from .helpers import VEHICLE, is_ack, is_type, udp_channel, udp_url, wait_for
from .mission_client import LossyProxy, MissionClient

HOME_ITEM = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 1, 1, 0, 0, 0, 0,
                        -353632620, 1491652370, 584.0)
LAT, LON = -353630000, 1491650000
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
ACCEPTED = M.MAV_MISSION_ACCEPTED


def waypoint(i: int, alt: float = 30.0) -> MissionItem:
    return MissionItem(M.MAV_CMD_NAV_WAYPOINT, REL, 0, 1, 0.0, 2.0, 0.0, 0.0,
                       LAT + 1000 * i, LON + 700 * i, alt)


MISSION_PLAN = [
    HOME_ITEM,
    MissionItem(M.MAV_CMD_NAV_TAKEOFF, REL, 0, 1, 0, 0, 0, 0, 0, 0, 20.0),
    waypoint(1), waypoint(2, 45.5),
    MissionItem(M.MAV_CMD_DO_JUMP, M.MAV_FRAME_MISSION, 0, 1, 2.0, 3.0, 0, 0, 0, 0, 0.0),
    MissionItem(M.MAV_CMD_NAV_RETURN_TO_LAUNCH, M.MAV_FRAME_MISSION, 0, 1, 0, 0, 0, 0, 0, 0, 0.0),
]
INC = M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
FENCE_PLAN = [
    MissionItem(M.MAV_CMD_NAV_FENCE_RETURN_POINT, M.MAV_FRAME_GLOBAL_INT, 0, 1, 0, 0, 0, 0, LAT, LON, 0.0),
    *[MissionItem(INC, M.MAV_FRAME_GLOBAL_INT, 0, 1, 4.0, 0, 0, 0, LAT + dx, LON + dy, 0.0)
      for dx, dy in ((-5000, -5000), (-5000, 5000), (5000, 5000), (5000, -5000))],
    MissionItem(M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, M.MAV_FRAME_GLOBAL_INT, 0, 1, 25.0, 0, 0, 0,
                LAT, LON + 100, 0.0),
]
RALLY_PLAN = [MissionItem(M.MAV_CMD_NAV_RALLY_POINT, REL, 0, 1, 0, 0, 0, 0,
                          LAT + 300 * i, LON - 200 * i, 40.0 + i) for i in range(3)]
PLANS = {M.MAV_MISSION_TYPE_MISSION: MISSION_PLAN, M.MAV_MISSION_TYPE_FENCE: FENCE_PLAN,
         M.MAV_MISSION_TYPE_RALLY: RALLY_PLAN}
TYPES = [pytest.param(t, id=n) for t, n in ((0, "mission"), (1, "fence"), (2, "rally"))]


def config(**mission) -> dict:
    conf = {"channels": [udp_channel("gcs")]}
    if mission:
        conf["mission"] = mission
    return conf


@pytest.fixture
def gcs(daemon, client):
    """A running daemon and a ground station (255, 190) that has said hello."""
    d = daemon(config())
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    return d, c


def home_only() -> list[MissionItem]:
    return [replace(HOME_ITEM, current=0)]


@pytest.mark.parametrize("mission_type", TYPES)
def test_a_ground_station_uploads_downloads_and_clears_each_plan(gcs, mission_type):
    _, c = gcs
    mc = MissionClient(c)
    plan = PLANS[mission_type]
    assert mc.upload(plan, mission_type) == ACCEPTED
    assert mc.download(mission_type) == plan
    assert mc.clear(mission_type) == ACCEPTED
    assert mc.download(mission_type) == []


def test_a_fresh_vehicle_has_home_as_its_mission(gcs):
    _, c = gcs
    assert MissionClient(c).download(0) == home_only()


def test_all_three_plans_survive_a_restart(daemon, client, tmp_path):
    first = daemon(config())
    c = client(udp_url(first.port("gcs")))
    c.heartbeat()
    mc = MissionClient(c)
    for mission_type, plan in PLANS.items():
        assert mc.upload(plan, mission_type) == ACCEPTED
    first.stop()
    state = tmp_path / "state"
    files = {p.name for p in state.glob("*.waypoints")}
    assert files == {"mission.waypoints", "fence.waypoints", "rally.waypoints"}

    second = daemon(config())
    c2 = client(udp_url(second.port("gcs")))
    c2.heartbeat()
    mc2 = MissionClient(c2)
    for mission_type, plan in PLANS.items():
        assert mc2.download(mission_type) == plan


def test_a_bad_plan_file_is_reported_and_kept_aside_not_overwritten(daemon, client, tmp_path, capfd):
    state = tmp_path / "state"
    state.mkdir()
    bad = "QGC WPL 110\n0\t1\t0\t16\t0\t0\t0\t0\t-35.36\t149.16\n"
    (state / "mission.waypoints").write_text(bad)
    (state / "rally.waypoints").write_text("QGC WPL 110\n0\t0\t3\t5100\t0\t0\t0\t0\t95.0\t149.0\t10\t1\n")
    d = daemon(config())
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    mc = MissionClient(c)
    assert mc.download(0) == home_only()
    assert mc.download(2) == []
    assert (state / "mission.waypoints.invalid").read_text() == bad
    assert not (state / "mission.waypoints").exists()
    out = capfd.readouterr().out
    assert "mission_file_invalid" in out and "line 2: expected 12 values, got 10" in out
    assert "item 0: MAV_MISSION_INVALID_PARAM5_X" in out
    assert mc.upload(MISSION_PLAN, 0) == ACCEPTED  # and the next plan is saved normally
    assert (state / "mission.waypoints.invalid").read_text() == bad


def test_a_second_ground_station_is_denied_while_the_first_uploads(daemon, client):
    d = daemon(config())
    a, b = client(udp_url(d.port("gcs")), 255, 190), client(udp_url(d.port("gcs")), 254, 190)
    a.heartbeat()
    b.heartbeat()
    mark_a = a.mark()
    a.send(M.MAVLink_mission_count_message(*VEHICLE, len(RALLY_PLAN), 2))
    assert wait_for(a, lambda r: r.type == "MISSION_REQUEST" and r.msg.seq == 0, since=mark_a)
    for msg in (M.MAVLink_mission_count_message(*VEHICLE, 2, 2),
                M.MAVLink_mission_clear_all_message(*VEHICLE, 2),
                M.MAVLink_mission_clear_all_message(*VEHICLE, M.MAV_MISSION_TYPE_ALL)):
        mark_b = b.mark()
        b.send(msg)
        ack = wait_for(b, lambda r: r.type == "MISSION_ACK", since=mark_b)
        assert ack is not None and ack.msg.type == M.MAV_MISSION_DENIED, msg
        assert ack.msg.target_system == 254
    assert MissionClient(a).upload(RALLY_PLAN, 2) == ACCEPTED  # a's upload was never disturbed


def test_clear_all_types_at_once(gcs):
    _, c = gcs
    mc = MissionClient(c)
    for mission_type, plan in PLANS.items():
        mc.upload(plan, mission_type)
    assert mc.clear(M.MAV_MISSION_TYPE_ALL) == ACCEPTED
    assert [len(mc.download(t)) for t in (0, 1, 2)] == [0, 0, 0]


def test_a_mission_transfers_over_mavlink1(daemon, client):
    """MAVLink1 has no mission_type field: only missions can travel on it (fence and rally
    uploads need MAVLink2, see the unit tests)."""
    d = daemon(config())
    c = client(udp_url(d.port("gcs")), version=1)
    c.heartbeat()
    mc = MissionClient(c)
    assert mc.upload(MISSION_PLAN, 0) == ACCEPTED
    assert mc.download(0) == MISSION_PLAN
    assert all(r.raw[0] == 0xFE for r in c.since(0) if r.src == VEHICLE)


def test_legacy_mission_item_and_mission_request_work_with_warnings(gcs):
    _, c = gcs
    mc = MissionClient(c)
    mark = c.mark()
    assert mc.upload(RALLY_PLAN, 2, use_int=False) == ACCEPTED
    ts, tc = VEHICLE
    c.send(M.MAVLink_mission_request_list_message(ts, tc, 2))
    c.send(M.MAVLink_mission_request_message(ts, tc, 1, 2))
    item = wait_for(c, is_type("MISSION_ITEM", VEHICLE), since=mark)
    assert item is not None and item.msg.seq == 1
    float32_deg = 1e-5  # MISSION_ITEM carries degrees as float32: about 4e-6 degree steps here
    assert item.msg.x == pytest.approx(RALLY_PLAN[1].x / 1e7, abs=float32_deg)
    assert item.msg.y == pytest.approx(RALLY_PLAN[1].y / 1e7, abs=float32_deg)
    for text in ("got MISSION_ITEM; GCS should send MISSION_ITEM_INT", "got MISSION_REQUEST; use MISSION_REQUEST_INT!"):
        assert wait_for(c, lambda r, t=text: r.type == "STATUSTEXT" and r.msg.text == t, since=mark), text
    for got, sent in zip(mc.download(2), RALLY_PLAN, strict=True):  # degrees x 1e7, within float32's steps
        assert abs(got.x - sent.x) <= 100 and abs(got.y - sent.y) <= 100
        assert got == MissionItem(sent.command, sent.frame, sent.current, sent.autocontinue, sent.param1,
                                  sent.param2, sent.param3, sent.param4, got.x, got.y, sent.z)


def test_mission_current_follows_the_plan_and_set_current(gcs):
    d, c = gcs
    changes = []
    d.gcs.nodes[0].plans.current_changed = lambda seq, reset_jumps: changes.append((seq, reset_jumps))
    assert MissionClient(c).upload(MISSION_PLAN, 0) == ACCEPTED
    mark = c.mark()
    current = wait_for(c, is_type("MISSION_CURRENT", VEHICLE), timeout=3.0, since=mark)
    assert current is not None
    assert (current.msg.seq, current.msg.total, current.msg.mission_state) == (
        0, len(MISSION_PLAN) - 1, M.MISSION_STATE_NOT_STARTED)

    mark = c.mark()
    c.send(M.MAVLink_mission_set_current_message(*VEHICLE, 3))
    # awaited, not timed: that it is pushed at once is pinned with a float clock (test_mission_service.py)
    current = wait_for(c, lambda r: r.type == "MISSION_CURRENT" and r.msg.seq == 3, timeout=5.0, since=mark)
    assert current is not None, "MISSION_SET_CURRENT is confirmed by MISSION_CURRENT"

    mark = c.mark()
    c.command_long(M.MAV_CMD_DO_SET_MISSION_CURRENT, len(MISSION_PLAN))
    ack = wait_for(c, is_ack(M.MAV_CMD_DO_SET_MISSION_CURRENT), since=mark)
    assert ack is not None and ack.msg.result == M.MAV_RESULT_DENIED
    mark = c.mark()
    c.command_long(M.MAV_CMD_DO_SET_MISSION_CURRENT, 2)
    ack = wait_for(c, is_ack(M.MAV_CMD_DO_SET_MISSION_CURRENT), since=mark)
    assert ack is not None and ack.msg.result == M.MAV_RESULT_ACCEPTED
    assert wait_for(c, lambda r: r.type == "MISSION_CURRENT" and r.msg.seq == 2, timeout=5.0, since=mark)
    mark = c.mark()
    c.command_long(M.MAV_CMD_DO_SET_MISSION_CURRENT, 1, 1)  # param2 = 1: reset jump counters, resume
    ack = wait_for(c, is_ack(M.MAV_CMD_DO_SET_MISSION_CURRENT), since=mark)
    assert ack is not None and ack.msg.result == M.MAV_RESULT_ACCEPTED
    assert changes == [(3, False), (2, False), (1, True)]  # what the vehicle's hook was told


def test_mission_current_says_no_mission_with_home_alone(gcs):
    _, c = gcs
    current = wait_for(c, is_type("MISSION_CURRENT", VEHICLE), timeout=3.0)
    assert current is not None
    assert (current.msg.total, current.msg.mission_state) == (0, M.MISSION_STATE_NO_MISSION)


def test_autopilot_version_advertises_mission_fence_and_rally(gcs):
    _, c = gcs
    mark = c.mark()
    c.command_long(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    version = wait_for(c, is_type("AUTOPILOT_VERSION", VEHICLE), since=mark)
    assert version is not None
    wanted = (M.MAV_PROTOCOL_CAPABILITY_MISSION_INT | M.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
              | M.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE | M.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY)
    assert version.msg.capabilities & wanted == wanted


@pytest.mark.slow
def test_500_item_mission_round_trips_through_20_percent_loss_each_way(daemon, client):
    d = daemon(config())
    proxy = LossyProxy(d.port("gcs"), loss=0.2, seed=20261122)
    try:
        c = client(udp_url(proxy.port))
        c.heartbeat()
        mc = MissionClient(c, timeout_s=0.15, window=5, deadline_s=120.0)
        plan = [HOME_ITEM] + [waypoint(i, 10.0 + i % 100) for i in range(1, 500)]
        started = time.monotonic()
        assert mc.upload(plan, 0) == ACCEPTED
        uploaded = time.monotonic()
        assert mc.download(0) == plan
        done = time.monotonic()
        print(f"500 items through 20 % loss each way: upload {uploaded - started:.1f} s, "
              f"download {done - uploaded:.1f} s, client resends {mc.resent}, "
              f"dropped {proxy.dropped}, forwarded {proxy.forwarded}")
        assert proxy.dropped["up"] > 50 and proxy.dropped["down"] > 50
    finally:
        proxy.close()


def test_a_clean_stop_cancels_an_upload_in_progress_and_keeps_the_plan(daemon, client, tmp_path):
    d = daemon(config())
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    assert MissionClient(c).upload(RALLY_PLAN, 2) == ACCEPTED
    mark = c.mark()
    c.send(M.MAVLink_mission_count_message(*VEHICLE, 5, 2))
    assert wait_for(c, lambda r: r.type == "MISSION_REQUEST" and r.msg.seq == 0, since=mark)
    d.stop()
    ack = wait_for(c, is_type("MISSION_ACK", VEHICLE), timeout=1.0, since=mark)
    assert ack is not None and ack.msg.type == M.MAV_MISSION_OPERATION_CANCELLED
    again = daemon(config())
    c2 = client(udp_url(again.port("gcs")))
    c2.heartbeat()
    assert MissionClient(c2).download(2) == RALLY_PLAN


def _upload_answering_late(c, plan: list[MissionItem], delay_s: float, deadline_s: float = 30.0):
    """Upload answering each MISSION_REQUEST `delay_s` after it arrives (a radio's round trip);
    returns (the ACK result, how many times each seq was requested)."""
    c.send(M.MAVLink_mission_count_message(*VEHICLE, len(plan), 0))
    asked: dict[int, int] = {}
    due: list[tuple[float, int]] = []
    seen, end = 0, time.monotonic() + deadline_s
    while time.monotonic() < end:
        c.read_available()
        for r in c.received[seen:]:
            if r.src != VEHICLE:
                continue
            if r.type == "MISSION_ACK":
                return r.msg.type, asked
            if r.type == "MISSION_REQUEST":
                asked[r.msg.seq] = asked.get(r.msg.seq, 0) + 1
                due.append((r.t + delay_s, r.msg.seq))
        seen = len(c.received)
        now = time.monotonic()
        for when, seq in [d for d in due if d[0] <= now]:
            due.remove((when, seq))
            it = plan[seq]
            c.send(M.MAVLink_mission_item_int_message(*VEHICLE, seq, it.frame, it.command, it.current,
                                                      it.autocontinue, it.param1, it.param2, it.param3,
                                                      it.param4, it.x, it.y, it.z, 0))
        time.sleep(0.002)
    raise AssertionError(f"no MISSION_ACK; requests {asked}")


@pytest.mark.alone
def test_a_57600_baud_link_is_never_asked_again_too_early(daemon, client):
    """A radio's byte budget (5 760 bytes/s, telemetry at the default rates on it) and a ground
    station that answers each request 80 ms later: the timeout follows the measured round trip,
    so no item is requested twice; and a 2 ms LAN gets the same upload about 20x faster.

    Runs alone (tests/conftest.py): the timeout is the round trip plus a few times its variation,
    as RFC 6298 sets it, so a ground station descheduled for longer than that once (four tests
    on two cores) is asked again, rightly ({16: 2} in a full parallel run). The timeout's rules,
    the backlog and the backoff, are pinned with a float clock in tests/unit/test_rtt.py and
    test_mission_transfer.py."""
    d = daemon({"channels": [udp_channel("radio", bandwidth=5760)]})
    c = client(udp_url(d.port("radio")))
    c.heartbeat()
    plan = [HOME_ITEM] + [waypoint(i) for i in range(1, 40)]
    started = time.monotonic()
    result, asked = _upload_answering_late(c, plan, delay_s=0.08)
    radio_s = time.monotonic() - started
    assert result == ACCEPTED
    assert asked == dict.fromkeys(range(len(plan)), 1), {s: n for s, n in asked.items() if n != 1}
    lan = daemon(config())
    c2 = client(udp_url(lan.port("gcs")))
    c2.heartbeat()
    started = time.monotonic()
    result, asked = _upload_answering_late(c2, plan, delay_s=0.002)
    lan_s = time.monotonic() - started
    assert result == ACCEPTED and asked == dict.fromkeys(range(len(plan)), 1)
    assert lan_s < radio_s / 5, (lan_s, radio_s)
