"""The ten-bucket deferred send scheduler, driven with a float clock (REFERENCE.md section 4)."""

from __future__ import annotations

import pytest

from gcsd.links.scheduler import MIN_INTERVAL_MS, NUM_BUCKETS, SERVICE_SHARE, SendScheduler, ServiceShare

HB = 0


class Recorder:
    def __init__(self, room: int | None = None) -> None:
        self.sent: list[tuple[float, int]] = []
        self.room = room
        self.now = 0.0

    def __call__(self, msgid: int) -> bool:
        if self.room is not None:
            if self.room <= 0:
                return False
            self.room -= 1
        self.sent.append((self.now, msgid))
        return True

    def ids(self):
        return [m for _, m in self.sent]


def run_for(s: SendScheduler, rec: Recorder, start: float, end: float) -> None:
    """Advance time deadline by deadline, as the channel task does."""
    now = start
    while now <= end + 1e-6:
        rec.now = now
        s.run(now, rec)
        nxt = s.next_deadline(now)
        if nxt is None:
            break
        now = max(nxt, now + 1e-6)


def count(rec: Recorder, msgid: int) -> int:
    return sum(1 for _, m in rec.sent if m == msgid)


def test_bucket_sends_at_its_rate_and_keeps_phase():
    s = SendScheduler(0.0)
    s.set_interval(30, 100, 0.0)
    rec = Recorder()
    run_for(s, rec, 0.0, 10.0)
    assert count(rec, 30) == 100
    times = [t for t, m in rec.sent if m == 30]
    assert abs(times[1] - times[0] - 0.1) < 1e-9


def test_messages_with_the_same_interval_share_a_bucket():
    s = SendScheduler(0.0)
    for msgid in (30, 33, 74):
        s.set_interval(msgid, 200, 0.0)
    rec = Recorder()
    run_for(s, rec, 0.0, 1.0)
    assert rec.ids() == [30, 33, 74] * 5


def test_heartbeat_special_slot_runs_at_its_own_interval():
    s = SendScheduler(0.0, special_ids=(HB,))
    s.set_interval(HB, 1000, 0.0)
    s.set_interval(30, 50, 0.0)
    rec = Recorder()
    run_for(s, rec, 0.0, 4.99)
    assert count(rec, HB) == 5  # 0, 1, 2, 3, 4 s
    assert count(rec, 30) == 99


def test_a_shorter_heartbeat_interval_applies_at_once_not_after_the_old_wait():
    # found by the fuzz suite: HEARTBEAT set to 10 s, then back to the default 1 s, stayed silent ~10 s
    s = SendScheduler(0.0, special_ids=(HB,))
    s.set_interval(HB, 10_000, 0.0)
    rec = Recorder()
    run_for(s, rec, 0.0, 0.5)
    s.set_interval(HB, 1000, 0.5)
    run_for(s, rec, 0.5, 3.0)
    assert [t for t, m in rec.sent if m == HB] == [0.0, 1.5, 2.5]


def test_pushed_message_is_sent_once_before_buckets():
    s = SendScheduler(0.0)
    s.set_interval(30, 100, 0.0)
    s.push(148)
    rec = Recorder()
    run_for(s, rec, 0.1, 1.0)
    assert rec.ids()[0] == 148
    assert count(rec, 148) == 1


def test_interval_zero_removes_the_message():
    s = SendScheduler(0.0)
    s.set_interval(30, 100, 0.0)
    s.set_interval(30, 0, 0.0)
    assert s.interval_ms(30) is None
    assert s.next_deadline(0.0) is None


def test_changing_interval_moves_the_message_to_a_new_bucket():
    s = SendScheduler(0.0)
    s.set_interval(30, 100, 0.0)
    s.set_interval(33, 100, 0.0)
    s.set_interval(30, 20, 0.0)
    assert (s.interval_ms(30), s.interval_ms(33)) == (20, 100)
    rec = Recorder()
    run_for(s, rec, 0.0, 1.0)
    assert count(rec, 30) == 50
    assert count(rec, 33) == 10


def test_eleventh_distinct_interval_joins_the_nearest_bucket():
    s = SendScheduler(0.0)
    for i in range(NUM_BUCKETS):
        s.set_interval(100 + i, 100 * (i + 1), 0.0)  # 100, 200, ... 1000 ms
    s.set_interval(200, 330, 0.0)
    assert s.interval_ms(200) == 300


def test_intervals_are_capped_at_the_loop_rate_and_60_s():
    s = SendScheduler(0.0)
    s.set_interval(30, 1, 0.0)
    s.set_interval(33, 90_000, 0.0)
    assert s.interval_ms(30) == MIN_INTERVAL_MS
    assert s.interval_ms(33) == 60_000


def test_full_link_stops_the_pass_and_retries_the_same_message():
    s = SendScheduler(0.0)
    for msgid in (30, 33, 74):
        s.set_interval(msgid, 100, 0.0)
    rec = Recorder(room=2)
    assert s.run(0.1, rec) is False
    assert rec.ids() == [30, 33]
    rec.room = 10
    s.run(0.1001, rec)
    assert rec.ids() == [30, 33, 74]


def test_slowdown_lengthens_the_reschedule_interval():
    s = SendScheduler(0.0)
    s.set_interval(30, 100, 0.0)
    s.slowdown_ms = 100
    rec = Recorder()
    run_for(s, rec, 0.0, 10.0)
    assert 48 <= count(rec, 30) <= 51


def test_slow_factor_multiplies_the_interval():
    s = SendScheduler(0.0)
    s.set_interval(30, 100, 0.0)
    s.slow_factor = 4
    rec = Recorder()
    run_for(s, rec, 0.0, 10.0)
    assert count(rec, 30) == 25


def test_clock_snaps_forward_after_a_stall_instead_of_bursting():
    s = SendScheduler(0.0)
    s.set_interval(30, 100, 0.0)
    rec = Recorder()
    run_for(s, rec, 0.0, 1.0)
    before = count(rec, 30)
    rec.now = 5.0
    s.run(5.0, rec)
    s.run(5.0, rec)
    assert count(rec, 30) - before == 1, "one send after the stall, not 40"


def test_deadline_is_now_while_pushed_messages_wait():
    s = SendScheduler(0.0)
    s.push(148)
    assert s.next_deadline(3.0) == 3.0


# --- the pass's parts and the services' share (ServiceShare) --------------------------------------

def test_streams_due_says_when_a_bucket_wants_the_link():
    s = SendScheduler(0.0, special_ids=(HB,))
    s.set_interval(HB, 1000, 0.0)
    assert not s.streams_due(5.0), "HEARTBEAT is no stream"
    s.set_interval(30, 100, 0.0)
    assert not s.streams_due(0.05) and s.streams_due(0.1)
    rec = Recorder(room=0)
    assert s.run_streams(0.1, rec) is False
    assert s.streams_due(0.1), "a bucket the link could not take is still due"
    rec.room = 10
    assert s.run_streams(0.1, rec) and not s.streams_due(0.1) and s.streams_due(0.2)


def test_run_urgent_sends_specials_and_pushed_but_no_bucket():
    s = SendScheduler(0.0, special_ids=(HB,))
    s.set_interval(HB, 1000, 0.0)
    s.set_interval(30, 100, 0.0)
    s.push(148)
    rec = Recorder()
    assert s.run_urgent(0.5, rec) and rec.ids() == [HB, 148]
    assert s.run_streams(0.5, rec) and rec.ids() == [HB, 148, 30]


RATE, DEPTH = 960.0, 280.0  # a 9600-baud link's budget and its bucket


def test_an_idle_share_admits_whatever_the_link_has():
    share = ServiceShare(RATE, DEPTH, 0.0)
    share.begin(enforced=False)
    share.charge(280, 0.0)  # spent, but no stream is due: the services may use the whole link
    assert share.admits(280, 280.0, DEPTH, 0.0) and not share.admits(281, 280.0, DEPTH, 0.0)
    assert share.wait_s(280, 0.0) == 0.0 and not share.waiting


def test_an_enforced_share_limits_the_services_to_their_part_of_the_rate():
    share = ServiceShare(RATE, DEPTH, 0.0)
    share.begin(enforced=True)
    assert share.admits(280, 280.0, DEPTH, 0.0)
    share.charge(280, 0.0)
    assert share.admits(280, 280.0, DEPTH, 0.0), "twice the link's depth: a burst of two frames"
    share.charge(280, 0.0)
    assert not share.admits(37, 280.0, DEPTH, 0.0) and not share.waiting, "spent: the streams' turn"
    assert share.wait_s(37, 0.0) == pytest.approx(37 / (RATE * SERVICE_SHARE))
    assert share.admits(37, 280.0, DEPTH, 37 / (RATE * SERVICE_SHARE))  # refilled at 2/3 of the rate


def test_a_service_within_its_share_waits_for_the_link_and_the_streams_hold_back():
    share = ServiceShare(RATE, DEPTH, 0.0)
    share.begin(enforced=True)
    assert not share.admits(280, 100.0, DEPTH, 0.0) and share.waiting
    share.begin(enforced=True)
    assert not share.admits(10_000, 100.0, DEPTH, 0.0) and not share.waiting, "never fits: nobody waits for it"


def test_charges_never_leave_the_share_in_debt():
    share = ServiceShare(RATE, DEPTH, 0.0)
    share.begin(enforced=True)
    share.charge(10_000, 0.0)  # a sender that did not ask first
    assert share.admits(37, 280.0, DEPTH, 37 / (RATE * SERVICE_SHARE))


def test_an_optional_copy_that_finds_no_room_waits_for_nothing():
    share = ServiceShare(RATE, DEPTH, 0.0)
    share.begin(enforced=True)
    assert not share.admits(280, 100.0, DEPTH, 0.0, waits=False) and not share.waiting


def test_the_streams_hold_back_for_a_waiting_service_at_most_a_second_without_it_sending():
    share = ServiceShare(RATE, DEPTH, 0.0)
    for now in (0.0, 0.5, 0.99):
        share.begin(enforced=True)
        assert not share.admits(280, 100.0, DEPTH, now) and share.holds_streams(now)
    share.begin(enforced=True)
    assert not share.admits(280, 100.0, DEPTH, 1.0) and not share.holds_streams(1.0), "forwarded frames keep the link"
    share.charge(280, 1.1)  # the service got its frame: a new wait may hold them again
    share.begin(enforced=True)
    assert not share.admits(37, 10.0, DEPTH, 1.2) and share.holds_streams(1.2)
    share.begin(enforced=True)
    assert share.admits(37, 280.0, DEPTH, 1.3) and not share.holds_streams(1.3), "nobody waits: nothing held"
