"""The mission-item transfer machine, driven with a float clock, for MISSION, FENCE and RALLY.

Every test talks to a real MissionTransfer over a real store (no private attributes) and reads
what the machine returns: `Send`s (decoded pymavlink messages), `Text`s and `PlanChanged`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission import (
    FenceStore,
    MissionItem,
    MissionStore,
    MissionTransfer,
    Origin,
    PlanChanged,
    RallyStore,
    Send,
    Text,
)
from gcsd.vehicle.mission.rtt import RttTable

GCS = Origin(255, 190, "gcs")
OTHER = Origin(250, 1, "other")  # another ground station
HOME = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 0, 1, 0, 0, 0, 0,
                   -353632620, 1491652370, 584.0)
LAT0, LON0 = -353600000, 1491600000


@dataclass(frozen=True)
class Kind:
    name: str
    mission_type: int
    store: Callable[..., object]
    item: Callable[[int], MissionItem]  # a valid item for position seq of any plan
    invalid: MissionItem  # an item the store rejects as it arrives
    invalid_result: int

    def plan(self, n: int, salt: int = 0) -> list[MissionItem]:
        return [self.item(seq + salt) for seq in range(n)]

    def served(self, items) -> list[MissionItem]:
        """What a download returns for an uploaded plan (mission: item 0 becomes home)."""
        items = list(items)
        if self.mission_type == M.MAV_MISSION_TYPE_MISSION and items:
            items[0] = replace(HOME, current=items[0].current)
        return items


def _waypoint(seq: int) -> MissionItem:
    return MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0, 1, 0, 0, 0, 0,
                       LAT0 + seq, LON0 + seq, 50.0 + seq)


def _circle(seq: int) -> MissionItem:
    return MissionItem(M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_FRAME_GLOBAL_INT, 0, 1,
                       100.0 + seq, 0, 0, 0, LAT0 + seq, LON0 + seq, 0.0)


def _rally(seq: int) -> MissionItem:
    return MissionItem(M.MAV_CMD_NAV_RALLY_POINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0, 1, 0, 0, 0, 0,
                       LAT0 + seq, LON0 - seq, 30.0 + seq)


def _mission_store(max_items=700, **kw):
    store = MissionStore(max_items, lambda: HOME, **kw)
    store.home_changed()
    return store


MISSION = Kind("mission", M.MAV_MISSION_TYPE_MISSION, _mission_store, _waypoint,
               MissionItem(31999, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT), M.MAV_MISSION_UNSUPPORTED)
FENCE = Kind("fence", M.MAV_MISSION_TYPE_FENCE, FenceStore, _circle,
             MissionItem(M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_FRAME_LOCAL_NED, param1=50.0),
             M.MAV_MISSION_UNSUPPORTED_FRAME)
RALLY = Kind("rally", M.MAV_MISSION_TYPE_RALLY, RallyStore, _rally,
             MissionItem(M.MAV_CMD_NAV_RALLY_POINT, M.MAV_FRAME_GLOBAL_INT, x=LAT0, y=LON0, z=40000.0),
             M.MAV_MISSION_INVALID_PARAM7)
KINDS = [pytest.param(k, id=k.name) for k in (MISSION, FENCE, RALLY)]


@pytest.fixture(params=KINDS)
def kind(request) -> Kind:
    return request.param


def machine(kind: Kind, max_items: int = 700, store=None, **kw) -> MissionTransfer:
    return MissionTransfer(store if store is not None else kind.store(max_items), **kw)


# --- reading what the machine returned ----------------------------------------------------------


def sent(out, name: str | None = None) -> list:
    return [o.msg for o in out if isinstance(o, Send) and (name is None or o.msg.get_type() == name)]


def acks(out) -> list[int]:
    """The MISSION_ACK results, the copies of an upload's final ACK counted once (see
    test_the_ack_that_ends_an_upload_is_sent_twice)."""
    results = [m.type for m in sent(out, "MISSION_ACK")]
    return [r for i, r in enumerate(results) if i == 0 or r != results[i - 1]]


def requests(out) -> list[int]:
    return [m.seq for m in sent(out, "MISSION_REQUEST")]


def texts(out) -> list[str]:
    return [o.text for o in out if isinstance(o, Text)]


def items_of(mt: MissionTransfer) -> list[MissionItem]:
    return list(mt.store.items())


def upload(mt: MissionTransfer, items, origin: Origin = GCS, now: float = 0.0) -> list:
    """A complete upload answering each request; returns every output."""
    out = mt.mission_count(origin, len(items), now)
    everything = list(out)
    while requests(out):
        seq = requests(out)[0]
        out = mt.mission_item(origin, seq, items[seq], False, now)
        everything += out
    return everything


def download(mt: MissionTransfer, origin: Origin = GCS) -> list[MissionItem]:
    [count] = sent(mt.mission_request_list(origin, 0.0), "MISSION_COUNT")
    got = []
    for seq in range(count.count):
        [m] = sent(mt.mission_request(origin, seq, False, 0.0), "MISSION_ITEM_INT")
        got.append(MissionItem(m.command, m.frame, m.current, m.autocontinue, m.param1, m.param2, m.param3,
                               m.param4, m.x, m.y, m.z))
    return got


# --- upload -----------------------------------------------------------------------------------------


def test_count_requests_item_0_with_mission_request_targeted_at_the_uploader(kind):
    mt = machine(kind)
    out = mt.mission_count(GCS, 3, 0.0)
    [send] = [o for o in out if isinstance(o, Send)]
    assert send.channel == GCS.channel
    assert send.msg.get_type() == "MISSION_REQUEST"  # msg 40, as ArduPilot sends it
    assert (send.msg.target_system, send.msg.target_component) == GCS.node
    assert (send.msg.seq, send.msg.mission_type) == (0, kind.mission_type)
    assert mt.receiving and mt.uploader == GCS.node and mt.upload_channel == GCS.channel


def test_each_item_requests_the_next_and_the_last_is_acknowledged_accepted(kind):
    mt = machine(kind)
    plan = kind.plan(4)
    mt.mission_count(GCS, 4, 0.0)
    for seq in range(3):
        assert requests(mt.mission_item(GCS, seq, plan[seq], False, 0.1)) == [seq + 1]
    out = mt.mission_item(GCS, 3, plan[3], False, 0.2)
    ack, _copy = sent(out, "MISSION_ACK")
    assert (ack.type, ack.mission_type, ack.target_system, ack.target_component) == (
        M.MAV_MISSION_ACCEPTED, kind.mission_type, 255, 190)
    assert PlanChanged(kind.mission_type, 4) in out
    assert not mt.receiving
    assert download(mt) == kind.served(plan)


def test_upload_is_atomic_the_old_plan_is_served_until_the_last_item_is_in(kind):
    mt = machine(kind)
    old = kind.plan(3)
    upload(mt, old)
    new = kind.plan(5, salt=100)
    mt.mission_count(GCS, 5, 1.0)
    for seq in range(4):
        mt.mission_item(GCS, seq, new[seq], False, 1.0)
    assert items_of(mt) == kind.served(old)
    mt.mission_item(GCS, 4, new[4], False, 1.0)
    assert items_of(mt) == kind.served(new)


def test_mission_completion_says_flight_plan_received():
    mt = machine(MISSION)
    assert "Flight plan received" in texts(upload(mt, MISSION.plan(2)))


def test_count_zero_clears_the_plan_and_is_accepted_at_once(kind):
    mt = machine(kind)
    upload(mt, kind.plan(3))
    out = mt.mission_count(GCS, 0, 1.0)
    assert acks(out) == [M.MAV_MISSION_ACCEPTED]
    assert PlanChanged(kind.mission_type, 0) in out
    assert mt.store.count() == 0 and not mt.receiving


def test_count_above_the_limit_is_no_space_with_the_limit_in_a_statustext(kind):
    mt = machine(kind, max_items=5)
    out = mt.mission_count(GCS, 6, 0.0)
    assert acks(out) == [M.MAV_MISSION_NO_SPACE]
    assert texts(out) == ["Only 5 items are supported"]
    assert not mt.receiving
    assert acks(upload(mt, kind.plan(5)))[-1] == M.MAV_MISSION_ACCEPTED  # the limit itself is fine


@pytest.mark.parametrize(("k", "result"), [
    pytest.param(MISSION, None, id="mission"),
    pytest.param(FENCE, M.MAV_MISSION_UNSUPPORTED, id="fence"),
    pytest.param(RALLY, M.MAV_MISSION_UNSUPPORTED, id="rally"),
])
def test_fence_and_rally_need_mavlink2_and_a_mission_does_not(k, result):
    mt = machine(k)
    v1 = Origin(255, 190, "radio", mavlink1=True)
    out = mt.mission_count(v1, 2, 0.0)
    if result is None:
        assert requests(out) == [0]
    else:
        assert acks(out) == [result] and texts(out) == ["Need mavlink2 for item transfer"]
        assert acks(mt.mission_write_partial_list(v1, 0, 0, 0.0)) == [result]


def test_a_second_uploader_is_denied_and_the_first_upload_goes_on(kind):
    mt = machine(kind)
    plan = kind.plan(3)
    mt.mission_count(GCS, 3, 0.0)
    mt.mission_item(GCS, 0, plan[0], False, 0.1)
    out = mt.mission_count(OTHER, 2, 0.2)
    assert acks(out) == [M.MAV_MISSION_DENIED]
    assert sent(out)[0].target_system == OTHER.sysid and out[0].channel == OTHER.channel
    assert acks(mt.mission_item(OTHER, 1, plan[1], False, 0.3)) == [M.MAV_MISSION_DENIED]
    assert acks(mt.mission_write_partial_list(OTHER, 0, 0, 0.3)) == [M.MAV_MISSION_DENIED]
    assert requests(mt.mission_item(GCS, 1, plan[1], False, 0.4)) == [2]
    assert acks(mt.mission_item(GCS, 2, plan[2], False, 0.5)) == [M.MAV_MISSION_ACCEPTED]
    assert items_of(mt) == kind.served(plan)


def test_another_component_of_the_same_system_is_another_uploader(kind):
    mt = machine(kind)
    mt.mission_count(GCS, 3, 0.0)
    assert acks(mt.mission_count(Origin(255, 191, "gcs"), 3, 0.1)) == [M.MAV_MISSION_DENIED]


def test_a_new_count_from_the_uploader_restarts_its_upload(kind):
    mt = machine(kind)
    first, second = kind.plan(4), kind.plan(2, salt=50)
    mt.mission_count(GCS, 4, 0.0)
    mt.mission_item(GCS, 0, first[0], False, 0.0)
    mt.mission_item(GCS, 1, first[1], False, 0.0)
    assert requests(mt.mission_count(GCS, 2, 0.5)) == [0]
    assert acks(upload_rest(mt, second, start=0)) == [M.MAV_MISSION_ACCEPTED]
    assert items_of(mt) == kind.served(second)


def upload_rest(mt, items, start: int, origin: Origin = GCS, now: float = 1.0) -> list:
    out: list = []
    for seq in range(start, len(items)):
        out = mt.mission_item(origin, seq, items[seq], False, now)
    return out


def test_an_out_of_order_item_is_invalid_sequence_and_the_upload_goes_on(kind):
    mt = machine(kind)
    plan = kind.plan(3)
    mt.mission_count(GCS, 3, 0.0)
    assert acks(mt.mission_item(GCS, 2, plan[2], False, 0.1)) == [M.MAV_MISSION_INVALID_SEQUENCE]
    assert mt.receiving
    assert requests(mt.mission_item(GCS, 0, plan[0], False, 0.2)) == [1]
    assert acks(upload_rest(mt, plan, start=1)) == [M.MAV_MISSION_ACCEPTED]
    assert items_of(mt) == kind.served(plan)


def test_a_duplicate_item_is_ignored_without_an_ack(kind):
    mt = machine(kind)
    plan = kind.plan(3)
    mt.mission_count(GCS, 3, 0.0)
    mt.mission_item(GCS, 0, plan[0], False, 0.1)
    mt.mission_item(GCS, 1, plan[1], False, 0.2)
    assert mt.mission_item(GCS, 1, plan[1], False, 0.3) == []
    assert mt.mission_item(GCS, 0, kind.item(99), False, 0.3) == []  # never replaces what was received
    assert acks(mt.mission_item(GCS, 2, plan[2], False, 0.4)) == [M.MAV_MISSION_ACCEPTED]
    assert items_of(mt) == kind.served(plan)


def test_an_item_when_nothing_is_being_received_is_an_error(kind):
    mt = machine(kind)
    assert acks(mt.mission_item(GCS, 0, kind.item(0), False, 0.0)) == [M.MAV_MISSION_ERROR]


def test_the_final_item_repeated_after_a_lost_ack_is_acknowledged_again(kind):
    mt = machine(kind)
    plan = kind.plan(3)
    out = upload(mt, plan)
    assert acks(out) == [M.MAV_MISSION_ACCEPTED]  # ... and suppose this ACK was lost
    again = mt.mission_item(GCS, 2, plan[2], False, 2.0)
    assert acks(again) == [M.MAV_MISSION_ACCEPTED]
    assert not any(isinstance(o, PlanChanged) for o in again)
    assert items_of(mt) == kind.served(plan)
    assert acks(mt.mission_item(OTHER, 2, plan[2], False, 2.0)) == [M.MAV_MISSION_ERROR]
    assert acks(mt.mission_item(GCS, 1, plan[1], False, 2.0)) == [M.MAV_MISSION_ERROR]


def test_the_repeated_final_item_gets_the_same_error_as_the_first_time():
    mt = machine(FENCE)
    bad = [FENCE.item(0), replace(FENCE.item(1), param1=0.0)]  # a circle of radius 0
    assert acks(upload(mt, bad)) == [M.MAV_MISSION_ERROR]
    assert acks(mt.mission_item(GCS, 1, bad[1], False, 1.0)) == [M.MAV_MISSION_ERROR]


def test_items_from_the_uploader_on_another_channel_are_taken_and_requests_stay_on_the_first(kind):
    mt = machine(kind)
    plan = kind.plan(3)
    mt.mission_count(GCS, 3, 0.0)
    other_link = Origin(GCS.sysid, GCS.compid, "backup-radio")
    out = mt.mission_item(other_link, 0, plan[0], False, 0.1)
    assert [o.channel for o in out if isinstance(o, Send)] == [GCS.channel]
    assert requests(out) == [1]
    mt.mission_item(other_link, 1, plan[1], False, 0.2)
    out = mt.mission_item(other_link, 2, plan[2], False, 0.3)
    assert acks(out) == [M.MAV_MISSION_ACCEPTED] and out[-1].channel == GCS.channel


def test_a_rejected_item_aborts_the_upload_with_its_result_and_keeps_the_old_plan(kind):
    mt = machine(kind)
    old = kind.plan(2)
    upload(mt, old)
    mt.mission_count(GCS, 3, 1.0)
    mt.mission_item(GCS, 0, kind.item(10), False, 1.0)
    out = mt.mission_item(GCS, 1, kind.invalid, False, 1.1)
    assert acks(out) == [kind.invalid_result]
    assert not mt.receiving
    assert items_of(mt) == kind.served(old)


def test_a_conversion_error_from_the_adapter_aborts_the_upload_with_that_result(kind):
    mt = machine(kind)
    mt.mission_count(GCS, 2, 0.0)
    assert acks(mt.mission_item(GCS, 0, M.MAV_MISSION_UNSUPPORTED_FRAME, True, 0.1)) == [
        M.MAV_MISSION_UNSUPPORTED_FRAME]
    assert not mt.receiving


def test_legacy_mission_item_is_taken_with_one_warning_per_upload(kind):
    mt = machine(kind)
    plan = kind.plan(3)
    mt.mission_count(GCS, 3, 0.0)
    warnings = []
    for seq in range(3):
        warnings += texts(mt.mission_item(GCS, seq, plan[seq], True, 0.1))
    assert warnings.count("got MISSION_ITEM; GCS should send MISSION_ITEM_INT") == 1
    assert items_of(mt) == kind.served(plan)


def test_a_mission_ack_from_the_uploader_cancels_its_upload_and_one_from_others_does_not(kind):
    mt = machine(kind)
    mt.mission_count(GCS, 3, 0.0)
    assert mt.mission_ack(OTHER, 0.1) == [] and mt.receiving
    assert mt.mission_ack(GCS, 0.2) == [] and not mt.receiving
    assert mt.next_deadline() is None


def test_a_save_that_fails_keeps_the_old_plan_and_acks_error(kind):
    saved: list = []

    def save(items):
        if len(saved) >= 1:
            raise OSError(28, "No space left on device")
        saved.append(items)

    store = kind.store(700, save=save) if kind is not MISSION else _mission_store(save=save)
    mt = machine(kind, store=store)
    old = kind.plan(2)
    upload(mt, old)
    out = upload(mt, kind.plan(3, salt=7), now=1.0)
    assert acks(out) == [M.MAV_MISSION_ERROR]
    assert any("No space left on device" in t for t in texts(out))
    assert items_of(mt) == kind.served(old)


# --- timeouts and retries ----------------------------------------------------------------------------


def test_the_ack_that_ends_an_upload_is_sent_twice(kind):
    """MAVSDK and MAVProxy never resend their last item: a lost final ACK would fail the upload."""
    mt = machine(kind)
    out = upload(mt, kind.plan(3))
    final = sent(out, "MISSION_ACK")
    assert [m.type for m in final] == [M.MAV_MISSION_ACCEPTED] * 2
    assert all(m.target_system == GCS.sysid and m.mission_type == kind.mission_type for m in final)
    again = sent(mt.mission_item(GCS, 2, kind.item(2), False, 1.0), "MISSION_ACK")  # a repeated last item
    assert [m.type for m in again] == [M.MAV_MISSION_ACCEPTED]  # answered once


def test_before_any_round_trip_is_measured_the_rerequest_waits_250_ms_then_backs_off(kind):
    mt = machine(kind)
    mt.mission_count(GCS, 3, 10.0)
    assert mt.next_deadline() == pytest.approx(10.25)
    assert mt.tick(10.249) == []
    assert requests(mt.tick(10.25)) == [0]
    assert mt.next_deadline() == pytest.approx(10.75)
    assert requests(mt.tick(10.75)) == [0]
    assert mt.next_deadline() == pytest.approx(11.75)  # x4, and retry_s is the ceiling anyway
    assert requests(mt.tick(11.75)) == [0]
    assert mt.next_deadline() == pytest.approx(12.75)


def test_a_small_retry_s_is_also_the_first_timeout(kind):
    mt = machine(kind, retry_s=0.1)
    mt.mission_count(GCS, 3, 0.0)
    assert requests(mt.tick(0.1)) == [0]


def test_the_first_round_trip_sets_the_timeout_as_rfc_6298_says(kind):
    """R = 0.25 s: SRTT = R, RTTVAR = R / 2, RTO = SRTT + 4 RTTVAR = 0.75 s."""
    mt = machine(kind)
    plan = kind.plan(3)
    mt.mission_count(GCS, 3, 10.0)
    assert requests(mt.mission_item(GCS, 0, plan[0], False, 10.25)) == [1]
    assert mt.next_deadline() == pytest.approx(11.0)
    assert mt.tick(10.999) == []
    assert requests(mt.tick(11.0)) == [1]


def test_a_fast_uploader_gets_a_lost_item_asked_for_again_within_tens_of_ms(kind):
    mt = machine(kind)
    plan = kind.plan(10)
    now = 0.0
    mt.mission_count(GCS, 10, now)
    for seq in range(5):  # answered in 2 ms each
        now += 0.002
        mt.mission_item(GCS, seq, plan[seq], False, now)
    # the request for item 5 (sent at `now`) is lost
    assert mt.next_deadline() - now == pytest.approx(0.02)  # the floor: SRTT 2 ms + G 10 ms < 20 ms
    assert requests(mt.tick(now + 0.02)) == [5]


def test_each_timeout_doubles_the_rerequest_interval_up_to_retry_s(kind):
    mt = machine(kind)
    plan = kind.plan(3)
    mt.mission_count(GCS, 3, 0.0)
    mt.mission_item(GCS, 0, plan[0], False, 0.1)  # RTO 0.1 + 4 * 0.05 = 0.3 s
    now = 0.1
    gaps = []
    for _ in range(5):
        deadline = mt.next_deadline()
        gaps.append(round(deadline - now, 6))
        now = deadline
        assert requests(mt.tick(now)) == [1]
    assert gaps == [0.3, 0.6, 1.0, 1.0, 1.0]


def test_an_item_answering_a_repeated_request_gives_no_sample_and_keeps_the_backoff(kind):
    """Karn's rule: it cannot be told which copy of the request the item answers."""
    mt = machine(kind)
    plan = kind.plan(4)
    mt.mission_count(GCS, 4, 0.0)
    mt.mission_item(GCS, 0, plan[0], False, 0.1)  # RTO 0.3 s
    assert requests(mt.tick(0.4)) == [1]  # backed off to 0.6 s
    mt.mission_item(GCS, 1, plan[1], False, 0.95)  # 0.85 s after the first request: no sample
    assert mt.next_deadline() == pytest.approx(0.95 + 0.6)
    mt.mission_item(GCS, 2, plan[2], False, 1.05)  # sampled 0.1 s: the backoff is cleared
    assert mt.next_deadline() == pytest.approx(1.05 + 0.25)  # SRTT 0.1, RTTVAR 0.0375


def test_a_slow_uploader_is_never_waited_for_longer_than_retry_s(kind):
    mt = machine(kind, retry_s=0.5)
    plan = kind.plan(3)
    mt.mission_count(GCS, 3, 0.0)
    mt.mission_item(GCS, 0, plan[0], False, 3.0)
    assert mt.next_deadline() == pytest.approx(3.5)


def test_the_rerequest_waits_for_the_links_backlog_and_radio_slowdown(kind):
    """What is queued ahead of the request at the link's bandwidth, and RADIO_STATUS's slowdown,
    both measured when the request goes out, come on top of the timeout."""
    backlog = {"gcs": 0.2}
    mt = machine(kind, queued_s=lambda channel: backlog[channel],
                 slowdown_s=lambda channel: 0.5 if channel == GCS.channel else 0.0)
    mt.mission_count(GCS, 3, 0.0)
    backlog["gcs"] = 0.0  # drained meanwhile: the deadline was fixed when the request was sent
    assert mt.next_deadline() == pytest.approx(0.25 + 0.2 + 0.5)
    assert mt.tick(0.94) == []
    assert requests(mt.tick(0.95)) == [0]
    assert mt.next_deadline() == pytest.approx(0.95 + 0.5 + 0.5)  # backed off; nothing queued now


def test_the_round_trip_estimate_belongs_to_the_uploader_and_is_shared_by_the_types():
    table = RttTable(initial_s=1.0, max_s=1.0)
    mission = MissionTransfer(MISSION.store(700), rtt=table)
    fence = MissionTransfer(FENCE.store(700), rtt=table)
    upload(mission, MISSION.plan(3))  # answered at once: RTO at the 20 ms floor
    fence.mission_count(GCS, 2, 5.0)
    assert fence.next_deadline() == pytest.approx(5.02)
    fence.mission_count(OTHER, 2, 6.0)  # DENIED: GCS owns the fence upload
    fence.mission_ack(GCS, 6.0)
    fence.mission_count(OTHER, 2, 7.0)  # another ground station: nothing measured yet
    assert fence.next_deadline() == pytest.approx(8.0)


def test_upload_aborts_after_8_s_without_a_valid_item(kind):
    mt = machine(kind)
    old = kind.plan(2)
    upload(mt, old)
    plan = kind.plan(3, salt=5)
    mt.mission_count(GCS, 3, 100.0)
    mt.mission_item(GCS, 0, plan[0], False, 101.0)
    for t in range(102, 109):  # re-requests meanwhile, and junk that does not count as progress
        mt.tick(float(t))
        mt.mission_item(GCS, 2, plan[2], False, float(t))
    assert mt.receiving
    out = mt.tick(109.0)
    assert texts(out) == [f"{kind.name.capitalize()} upload timeout"]
    assert acks(out) == [M.MAV_MISSION_OPERATION_CANCELLED]
    assert sent(out, "MISSION_ACK")[0].target_system == GCS.sysid
    assert not mt.receiving and mt.next_deadline() is None
    assert items_of(mt) == kind.served(old)
    assert acks(mt.mission_item(GCS, 1, plan[1], False, 109.5)) == [M.MAV_MISSION_ERROR]
    # the uploader vanished: another ground station downloads the old plan at once
    [count] = sent(mt.mission_request_list(OTHER, 109.6), "MISSION_COUNT")
    assert count.count == len(kind.served(old))


def test_the_abort_deadline_is_8_s_after_the_last_valid_item(kind):
    mt = machine(kind, retry_s=10.0, rtt=RttTable(initial_s=10.0, max_s=10.0))  # no re-request before
    mt.mission_count(GCS, 3, 0.0)
    assert mt.next_deadline() == pytest.approx(8.0)
    mt.mission_item(GCS, 0, kind.item(0), False, 5.0)
    assert mt.next_deadline() == pytest.approx(13.0)


def test_an_upload_survives_lost_requests_and_lost_items(kind):
    """Every other request and every third item is lost; the re-requests recover all of them."""
    mt = machine(kind)
    plan = kind.plan(12)
    now = 0.0
    pending = requests(mt.mission_count(GCS, len(plan), now))
    delivered = 0
    lost = 0
    done = []
    for _ in range(1000):
        for seq in pending:
            lost += 1
            if lost % 2:
                continue  # the request was lost
            delivered += 1
            if delivered % 3 == 0:
                continue  # the item was lost
            out = mt.mission_item(GCS, seq, plan[seq], False, now)
            done = acks(out)
            pending = requests(out)
            break
        else:
            now = mt.next_deadline()
            if now is None:
                break
            out = mt.tick(now)
            done, pending = acks(out), requests(out)
        if done:
            break
    assert done == [M.MAV_MISSION_ACCEPTED]
    assert items_of(mt) == kind.served(plan)
    assert now < 8.0 * len(plan)


# --- download ----------------------------------------------------------------------------------------


def test_request_list_answers_the_count_targeted_at_the_requester(kind):
    mt = machine(kind)
    upload(mt, kind.plan(4))
    [count] = sent(mt.mission_request_list(OTHER, 1.0), "MISSION_COUNT")
    assert (count.count, count.mission_type, count.target_system, count.target_component) == (
        4, kind.mission_type, OTHER.sysid, OTHER.compid)


def test_downloads_are_denied_while_receiving_even_to_the_uploader(kind):
    mt = machine(kind)
    upload(mt, kind.plan(2))
    mt.mission_count(GCS, 3, 1.0)
    for origin in (GCS, OTHER):
        assert acks(mt.mission_request_list(origin, 1.1)) == [M.MAV_MISSION_DENIED]
        assert acks(mt.mission_request(origin, 0, False, 1.1)) == [M.MAV_MISSION_DENIED]


def test_request_int_out_of_range_corrects_the_count_then_says_invalid_sequence(kind):
    mt = machine(kind)
    upload(mt, kind.plan(2))
    out = mt.mission_request(GCS, 2, False, 1.0)
    assert [m.get_type() for m in sent(out)] == ["MISSION_COUNT", "MISSION_ACK"]
    assert sent(out)[0].count == 2 and acks(out) == [M.MAV_MISSION_INVALID_SEQUENCE]


def test_pipelined_out_of_order_requests_are_each_answered(kind):
    mt = machine(kind)
    plan = kind.plan(6)
    upload(mt, plan)
    answered = {}
    copies = []
    for seq in (4, 0, 2, 1, 3, 2, 5):  # MAVProxy asks 5 ahead and re-asks the missing ones
        replies = sent(mt.mission_request(OTHER, seq, False, 1.0), "MISSION_ITEM_INT")
        copies.append(len(replies))
        m = replies[0]
        assert (m.target_system, m.target_component, m.mission_type) == (*OTHER.node, kind.mission_type)
        answered[m.seq] = MissionItem(m.command, m.frame, m.current, m.autocontinue, m.param1, m.param2,
                                      m.param3, m.param4, m.x, m.y, m.z)
    assert copies == [1, 1, 1, 1, 1, 2, 1]  # 2 was asked again: its reply was lost
    assert [answered[s] for s in range(6)] == kind.served(plan)


def test_legacy_request_answers_mission_item_in_degrees_with_one_warning_per_list(kind):
    mt = machine(kind)
    plan = kind.plan(3)
    upload(mt, plan)
    mt.mission_request_list(GCS, 1.0)
    warnings = []
    for seq in range(3):
        out = mt.mission_request(GCS, seq, True, 1.0)
        warnings += texts(out)
        [m] = sent(out, "MISSION_ITEM")
        expected = kind.served(plan)[seq]
        assert m.x == pytest.approx(expected.x / 1e7, abs=1e-7)
        assert m.y == pytest.approx(expected.y / 1e7, abs=1e-7)
    assert warnings == ["got MISSION_REQUEST; use MISSION_REQUEST_INT!"]
    mt.mission_request_list(GCS, 2.0)
    assert texts(mt.mission_request(GCS, 0, True, 2.0)) == ["got MISSION_REQUEST; use MISSION_REQUEST_INT!"]


def test_legacy_request_is_answered_even_while_receiving(kind):
    mt = machine(kind)
    upload(mt, kind.plan(2))
    mt.mission_count(GCS, 3, 1.0)
    assert len(sent(mt.mission_request(OTHER, 1, True, 1.0), "MISSION_ITEM")) == 1


def test_mission_item_0_is_home_and_readable_even_with_an_empty_mission():
    mt = machine(MISSION)
    upload(mt, MISSION.plan(3))
    mt.mission_clear_all(GCS, 1.0)
    [count] = sent(mt.mission_request_list(GCS, 1.0), "MISSION_COUNT")
    assert count.count == 0
    [m] = sent(mt.mission_request(GCS, 0, False, 1.0), "MISSION_ITEM_INT")
    assert (m.command, m.frame, m.x, m.y, m.z) == (HOME.command, HOME.frame, HOME.x, HOME.y, HOME.z)


def test_an_uploaded_item_0_is_replaced_by_home_keeping_its_current_flag():
    mt = machine(MISSION)
    plan = [replace(MISSION.item(0), current=1), *MISSION.plan(2)[1:]]
    upload(mt, plan)
    assert download(mt)[0] == replace(HOME, current=1)


# --- partial write ------------------------------------------------------------------------------------


def test_partial_write_requests_start_to_end_and_replaces_only_those(kind):
    mt = machine(kind)
    plan = kind.plan(5)
    upload(mt, plan)
    new = {2: kind.item(102), 3: kind.item(103)}
    out = mt.mission_write_partial_list(GCS, 2, 3, 1.0)
    assert requests(out) == [2]
    assert requests(mt.mission_item(GCS, 2, new[2], False, 1.1)) == [3]
    out = mt.mission_item(GCS, 3, new[3], False, 1.2)
    assert acks(out) == [M.MAV_MISSION_ACCEPTED]
    assert items_of(mt) == kind.served([plan[0], plan[1], new[2], new[3], plan[4]])


def test_partial_write_starting_at_the_count_appends(kind):
    mt = machine(kind)
    plan = kind.plan(3)
    upload(mt, plan)
    assert requests(mt.mission_write_partial_list(GCS, 3, 3, 1.0)) == [3]
    assert acks(mt.mission_item(GCS, 3, kind.item(3), False, 1.1)) == [M.MAV_MISSION_ACCEPTED]
    assert items_of(mt) == kind.served(kind.plan(4))


@pytest.mark.parametrize(("start", "end"), [(4, 4), (0, 4), (2, 1), (-1, 2), (0, -1)])
def test_partial_write_out_of_bounds_is_rejected_with_error(kind, start, end):
    mt = machine(kind)
    upload(mt, kind.plan(3))
    out = mt.mission_write_partial_list(GCS, start, end, 1.0)
    assert acks(out) == [M.MAV_MISSION_ERROR]
    assert texts(out) == ["Flight plan update rejected"]
    assert not mt.receiving


def test_partial_write_beyond_the_limit_is_no_space(kind):
    mt = machine(kind, max_items=3)
    upload(mt, kind.plan(3))
    out = mt.mission_write_partial_list(GCS, 3, 3, 1.0)
    assert acks(out) == [M.MAV_MISSION_NO_SPACE] and texts(out) == ["Only 3 items are supported"]


def test_partial_write_is_denied_while_receiving_even_from_the_uploader(kind):
    mt = machine(kind)
    upload(mt, kind.plan(3))
    mt.mission_count(GCS, 3, 1.0)
    assert acks(mt.mission_write_partial_list(GCS, 0, 0, 1.1)) == [M.MAV_MISSION_DENIED]
    assert mt.receiving and mt.uploader == GCS.node


def test_partial_write_that_makes_the_whole_plan_invalid_keeps_the_old_one():
    mt = machine(FENCE)
    plan = FENCE.plan(3)
    upload(mt, plan)
    mt.mission_write_partial_list(GCS, 1, 1, 1.0)
    out = mt.mission_item(GCS, 1, replace(plan[1], param1=-5.0), False, 1.1)
    assert acks(out) == [M.MAV_MISSION_ERROR] and texts(out) == ["Fence: circle at item 1 needs a radius > 0"]
    assert items_of(mt) == plan


# --- clear ---------------------------------------------------------------------------------------------


def test_clear_all_empties_the_plan_and_is_accepted(kind):
    mt = machine(kind)
    upload(mt, kind.plan(3))
    out = mt.mission_clear_all(OTHER, 1.0)
    assert acks(out) == [M.MAV_MISSION_ACCEPTED] and PlanChanged(kind.mission_type, 0) in out
    assert sent(out, "MISSION_ACK")[0].target_system == OTHER.sysid
    assert mt.store.count() == 0


def test_clear_during_another_nodes_upload_is_denied_and_the_upload_goes_on(kind):
    mt = machine(kind)
    plan = kind.plan(2)
    mt.mission_count(GCS, 2, 0.0)
    assert acks(mt.mission_clear_all(OTHER, 0.1)) == [M.MAV_MISSION_DENIED]
    assert mt.denies(OTHER) and not mt.denies(GCS)
    mt.mission_item(GCS, 0, plan[0], False, 0.2)
    assert acks(mt.mission_item(GCS, 1, plan[1], False, 0.3)) == [M.MAV_MISSION_ACCEPTED]


def test_clear_from_the_uploader_cancels_its_upload(kind):
    mt = machine(kind)
    mt.mission_count(GCS, 2, 0.0)
    assert acks(mt.mission_clear_all(GCS, 0.1)) == [M.MAV_MISSION_ACCEPTED]
    assert not mt.receiving


def test_clear_refused_by_the_vehicle_is_an_error_and_keeps_the_mission():
    store = MissionStore(700, lambda: HOME, clear_refused=lambda: True)
    mt = machine(MISSION, store=store)
    plan = MISSION.plan(3)
    upload(mt, plan)
    assert acks(mt.mission_clear_all(GCS, 1.0)) == [M.MAV_MISSION_ERROR]
    assert items_of(mt) == MISSION.served(plan)


# --- every result code ----------------------------------------------------------------------------------


def _result_of_item(kind: Kind, item: MissionItem, count: int = 3) -> int:
    mt = machine(kind)
    mt.mission_count(GCS, count, 0.0)
    mt.mission_item(GCS, 0, kind.item(0), False, 0.0)
    return acks(mt.mission_item(GCS, 1, item, False, 0.0))[0]


def _result_after_count(kind: Kind, then) -> int:
    mt = machine(kind)
    mt.mission_count(GCS, 2, 0.0)
    return acks(then(mt))[0]


@pytest.mark.parametrize(("name", "scenario"), [
    ("ACCEPTED", lambda: acks(upload(machine(RALLY), RALLY.plan(1)))[0]),
    ("ERROR", lambda: acks(machine(FENCE).mission_item(GCS, 0, FENCE.item(0), False, 0.0))[0]),
    ("UNSUPPORTED_FRAME", lambda: _result_of_item(RALLY, replace(RALLY.item(1), frame=M.MAV_FRAME_BODY_FRD))),
    ("UNSUPPORTED", lambda: _result_of_item(FENCE, MISSION.item(1))),
    ("NO_SPACE", lambda: acks(machine(MISSION, max_items=2).mission_count(GCS, 3, 0.0))[0]),
    ("INVALID_PARAM1", lambda: _result_of_item(FENCE, replace(FENCE.item(1), command=5001, param1=256.0))),
    ("INVALID_PARAM5_X", lambda: _result_of_item(RALLY, replace(RALLY.item(1), x=900_000_001))),
    ("INVALID_PARAM6_Y", lambda: _result_of_item(MISSION, replace(MISSION.item(1), y=-1_800_000_001))),
    ("INVALID_PARAM7", lambda: _result_of_item(RALLY, replace(RALLY.item(1), z=-40000.0))),
    ("INVALID_SEQUENCE", lambda: acks(machine(FENCE).mission_request(GCS, 0, False, 0.0))[0]),
    ("DENIED", lambda: _result_after_count(MISSION, lambda mt: mt.mission_count(OTHER, 2, 0.0))),
    ("OPERATION_CANCELLED", lambda: _result_after_count(RALLY, lambda mt: mt.tick(8.0))),
])
def test_each_result_code_is_produced(name, scenario):
    assert scenario() == getattr(M, f"MAV_MISSION_{name}")


def test_a_do_jump_may_target_any_item_of_the_plan_the_upload_makes_but_not_beyond():
    jump = lambda target: MissionItem(M.MAV_CMD_DO_JUMP, M.MAV_FRAME_MISSION, param1=target, param2=1)
    mt = machine(MISSION)
    upload(mt, MISSION.plan(3))
    mt.mission_write_partial_list(GCS, 3, 3, 1.0)
    # item 3 is appended by this very upload
    assert acks(mt.mission_item(GCS, 3, jump(3), False, 1.0)) == [M.MAV_MISSION_ACCEPTED]
    mt.mission_count(GCS, 3, 2.0)
    mt.mission_item(GCS, 0, MISSION.item(0), False, 2.0)
    assert acks(mt.mission_item(GCS, 1, jump(3), False, 2.0)) == [M.MAV_MISSION_ERROR]  # the new plan has 3


# --- whole plans (FTP @MISSION/*.dat) ---------------------------------------------------------------


def test_a_whole_plan_written_at_once_replaces_the_plan(kind):
    mt = machine(kind)
    plan = kind.plan(4)
    result, out = mt.write_plan(plan, 0.0)
    assert result == M.MAV_MISSION_ACCEPTED and PlanChanged(kind.mission_type, 4) in out
    assert items_of(mt) == kind.served(plan)


def test_a_whole_plan_gets_the_checks_of_an_upload_and_the_old_plan_stays(kind):
    mt = machine(kind, max_items=4)
    old = kind.plan(2)
    mt.write_plan(old, 0.0)
    assert mt.write_plan(kind.plan(5), 0.0)[0] == M.MAV_MISSION_NO_SPACE
    assert mt.write_plan([kind.item(0), kind.invalid], 0.0)[0] == kind.invalid_result
    mt.mission_count(GCS, 2, 1.0)
    assert mt.write_plan(kind.plan(3), 1.0)[0] == M.MAV_MISSION_DENIED
    assert items_of(mt) == kind.served(old)


def test_a_whole_fence_invalid_as_a_whole_is_an_error_with_the_reason():
    mt = machine(FENCE)
    result, out = mt.write_plan([replace(FENCE.item(0), param1=0.0)], 0.0)
    assert result == M.MAV_MISSION_ERROR and texts(out) == ["Fence: circle at item 0 needs a radius > 0"]


def test_an_item_asked_for_again_is_sent_twice_because_a_reply_was_lost(kind):
    mt = machine(kind)
    upload(mt, kind.plan(3))
    mt.mission_request_list(GCS, 1.0)
    assert len(sent(mt.mission_request(GCS, 1, False, 1.0), "MISSION_ITEM_INT")) == 1
    assert len(sent(mt.mission_request(GCS, 2, False, 1.1), "MISSION_ITEM_INT")) == 1
    again = sent(mt.mission_request(GCS, 1, False, 1.6), "MISSION_ITEM_INT")
    assert [m.seq for m in again] == [1, 1]
    assert len(sent(mt.mission_request(OTHER, 1, False, 1.7), "MISSION_ITEM_INT")) == 1  # per requester
    assert len(sent(mt.mission_request(GCS, 1, True, 1.8), "MISSION_ITEM")) == 2
    mt.mission_request_list(GCS, 2.0)  # a new download starts afresh
    assert len(sent(mt.mission_request(GCS, 1, False, 2.1), "MISSION_ITEM_INT")) == 1


def test_download_bookkeeping_is_bounded_to_8_ground_stations(kind):
    mt = machine(kind)
    upload(mt, kind.plan(2))
    mt.mission_request(GCS, 0, False, 1.0)
    for sysid in range(1, 9):  # eight others push GCS out
        mt.mission_request(Origin(sysid, 1, "other"), 0, False, 1.0)
    assert len(sent(mt.mission_request(GCS, 0, False, 1.1), "MISSION_ITEM_INT")) == 1


def test_a_stopping_vehicle_cancels_an_upload_in_progress_and_keeps_the_old_plan(kind):
    mt = machine(kind)
    old = kind.plan(2)
    upload(mt, old)
    assert mt.cancel(1.0) == []  # nothing in progress: nothing to say
    mt.mission_count(GCS, 3, 2.0)
    mt.mission_item(GCS, 0, kind.item(50), False, 2.1)
    out = mt.cancel(2.2)
    assert acks(out) == [M.MAV_MISSION_OPERATION_CANCELLED] and out[0].channel == GCS.channel
    assert not mt.receiving and items_of(mt) == kind.served(old)
