"""Mission downloads through a lossy link (issue 17, item 13): the pure helper (download.py) and
the transfer machine with `lossy` on, with a float `now`; and the per-source loss the parser
measures from sequence gaps."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission import MissionItem, MissionStore, MissionTransfer, Origin
from gcsd.vehicle.mission.download import (
    COUNT_COPIES,
    ITEM_COPIES,
    LOSSY,
    MAX_REPUSH,
    MAX_REQUESTERS,
    MIN_FRAMES,
    REPUSH_S,
    WINDOW,
    DownloadAssist,
    is_lossy,
)
from gcsd.vehicle.mission.effects import Send
from gcsd.wire.codec import FrameParser

GCS = Origin(255, 190, "gcs")
N = 40


def transfer(lossy: bool) -> MissionTransfer:
    home = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 0, 1, 0, 0, 0, 0, 1, 1, 100.0)
    store = MissionStore(700, lambda: home)
    store.replace(tuple([home] + [MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0, 1,
                                              0, 0, 0, 0, 10 * i, 10 * i, 10.0) for i in range(1, N)]))
    return MissionTransfer(store, lossy=lambda origin: lossy)


def seqs(out, optional: bool | None = None) -> list[int]:
    return [o.msg.seq for o in out if isinstance(o, Send) and o.msg.get_type() == "MISSION_ITEM_INT"
            and (optional is None or o.optional == optional)]


# --- DownloadAssist ---------------------------------------------------------------------------

def test_a_request_pushes_the_window_after_it_bounded_by_the_count():
    a = DownloadAssist()
    assert a.requested((255, 190), "gcs", 3, N, False, 0.0) == range(4, 3 + WINDOW)
    assert a.requested((255, 190), "gcs", N - 2, N, False, 0.1) == range(N - 1, N)


def test_a_silent_requester_gets_the_window_from_its_highest_request_again_every_repush_s():
    a = DownloadAssist()
    a.requested((255, 190), "gcs", 5, N, False, 10.0)
    a.requested((255, 190), "gcs", 4, N, False, 10.1)  # an older request again: the top stays 5
    assert a.next_deadline() == pytest.approx(10.1 + REPUSH_S)
    assert a.tick(10.1 + REPUSH_S - 0.01) == []
    [push] = a.tick(10.1 + REPUSH_S)
    assert (push.channel, push.node, push.seqs) == ("gcs", (255, 190), range(5, 5 + WINDOW))
    assert a.next_deadline() == pytest.approx(10.1 + 2 * REPUSH_S)


def test_repushes_stop_after_max_repush_silent_rounds_and_a_new_top_restarts_the_count():
    a = DownloadAssist()
    a.requested((255, 190), "gcs", 5, N, False, 0.0)
    now, pushes = 0.0, 0
    for _ in range(MAX_REPUSH + 5):
        now += REPUSH_S
        pushes += len(a.tick(now))
    assert pushes == MAX_REPUSH and a.next_deadline() is None
    a.requested((255, 190), "gcs", 6, N, False, now)  # heard again: followed again
    assert len(a.tick(now + REPUSH_S)) == 1


def test_the_requesters_ack_or_a_new_list_ends_its_pushes_and_the_table_is_bounded():
    a = DownloadAssist()
    a.requested((255, 190), "gcs", 5, N, False, 0.0)
    a.finish((255, 190))
    assert a.tick(10.0) == [] and a.next_deadline() is None
    for sysid in range(MAX_REQUESTERS + 3):
        a.requested((sysid, 1), "gcs", 0, N, False, 0.0)
    assert len(a.channels()) == 1 and len(a.tick(REPUSH_S)) == MAX_REQUESTERS


@pytest.mark.parametrize(("loss", "frames", "lossy"), [
    (0.2, 50, True), (LOSSY, MIN_FRAMES, True), (0.01, 500, False), (0.5, MIN_FRAMES - 1, False)])
def test_a_link_is_lossy_from_a_measured_share_over_enough_frames(loss, frames, lossy):
    assert is_lossy(loss, frames) is lossy


# --- the transfer machine ------------------------------------------------------------------------

def test_on_a_lossy_link_the_count_goes_three_times_the_copies_optional():
    out = transfer(True).mission_request_list(GCS, 0.0)
    assert [o.msg.count for o in out] == [N] * COUNT_COPIES
    assert [o.optional for o in out] == [False] + [True] * (COUNT_COPIES - 1)
    assert len(transfer(False).mission_request_list(GCS, 0.0)) == 1, "a clean link: one"


def test_on_a_lossy_link_an_answer_goes_twice_and_the_next_items_follow_it_in_order():
    mt = transfer(True)
    mt.mission_request_list(GCS, 0.0)
    out = mt.mission_request(GCS, 3, False, 0.1)
    assert seqs(out) == [3] * ITEM_COPIES + list(range(4, 3 + WINDOW))
    assert seqs(out, optional=False) == [3], "only the answer itself is owed"
    clean = transfer(False)
    clean.mission_request_list(GCS, 0.0)
    assert seqs(clean.mission_request(GCS, 3, False, 0.1)) == [3]
    assert clean.next_deadline() is None, "nothing to push on a clean link"


def test_a_silent_requester_on_a_lossy_link_gets_the_window_again_until_its_ack():
    mt = transfer(True)
    mt.mission_request_list(GCS, 0.0)
    mt.mission_request(GCS, N - 3, False, 1.0)
    assert mt.next_deadline() == pytest.approx(1.0 + REPUSH_S)
    assert seqs(mt.tick(1.0 + REPUSH_S), optional=True) == [N - 3, N - 2, N - 1]
    mt.mission_ack(GCS, 1.5)  # the download's end
    assert mt.tick(5.0) == [] and mt.next_deadline() is None


def test_a_download_from_the_lossy_machine_still_reads_every_item_in_order():
    mt = transfer(True)
    [count, *_] = mt.mission_request_list(GCS, 0.0)
    got = []
    for seq in range(count.msg.count):
        got.append(next(o.msg for o in mt.mission_request(GCS, seq, False, 0.01 * seq) if not o.optional).seq)
    assert got == list(range(N))


# --- loss measured from sequence gaps ------------------------------------------------------------

def frames(seqs_sent) -> bytes:
    mav = M.MAVLink(None, srcSystem=255, srcComponent=190)
    out = b""
    for seq in seqs_sent:
        mav.seq = seq & 0xFF
        out += M.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3).pack(mav)
    return out


def test_the_parser_measures_a_sources_loss_from_its_sequence_gaps():
    parser = FrameParser()
    sent = [s for s in range(200) if s % 5 != 0]  # every fifth frame lost: 20 %
    parser.feed(frames(sent))
    loss, measured = parser.stats.loss((255, 190))
    assert loss == pytest.approx(0.2, abs=0.01) and measured > 150
    assert parser.stats.loss((1, 1)) == (0.0, 0), "never heard"
    clean = FrameParser()
    clean.feed(frames(range(300)))  # the sequence wraps at 256: no gap
    assert clean.stats.loss((255, 190))[0] == 0.0
