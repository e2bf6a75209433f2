"""The log protocol's server core (as ArduPilot's AP_Logger_MAVLinkLogTransfer), the log
directory (listing, chunking, resuming at any offset, rotation) and LOG_DATA's fast packing."""

from __future__ import annotations

import os

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.payloads.logs.fastpack import LogData
from gcsd.payloads.logs.store import LogEntry, LogStore
from gcsd.payloads.logs.transfer import COUNT_MAX as COUNT
from gcsd.payloads.logs.transfer import Chunk, EntryMsg, LogTransfer


def entries(*sizes: int) -> list[LogEntry]:
    return [LogEntry(i + 1, f"{i + 1:08d}.BIN", size, 1_700_000_000 + i) for i, size in enumerate(sizes)]


def serve(t: LogTransfer, data: dict[str, bytes]) -> list:
    """Run the transfer to IDLE, reading chunks from `data`; what went out, in order."""
    out = []
    while (item := t.next()) is not None:
        if isinstance(item, EntryMsg):
            out.append(item)
            t.taken()
        else:
            got = data[item.name][item.ofs:item.ofs + item.count]
            out.append((item.ofs, got))
            t.sent(len(got))
    return out


def test_list_sends_one_entry_per_log_with_1_based_ids():
    t = LogTransfer()
    t.request_list(entries(10, 20, 30), 0, 0xFFFF)
    assert serve(t, {}) == [EntryMsg(1, 3, 3, 1_700_000_000, 10), EntryMsg(2, 3, 3, 1_700_000_001, 20),
                            EntryMsg(3, 3, 3, 1_700_000_002, 30)]
    assert not t.busy


def test_list_with_no_logs_is_one_entry_with_num_logs_0():
    t = LogTransfer()
    t.request_list([], 0, 0xFFFF)
    assert serve(t, {}) == [EntryMsg(0, 0, 0, 0, 0)]


def test_list_of_a_range():
    t = LogTransfer()
    t.request_list(entries(1, 2, 3, 4), 2, 3)
    assert [e.id for e in serve(t, {})] == [2, 3]


def test_data_comes_in_90_byte_chunks_ending_on_a_short_one():
    data = {"00000001.BIN": bytes(range(200))}
    t = LogTransfer()
    t.request_data(entries(200), 1, 0, 0xFFFFFFFF)
    out = serve(t, data)
    assert [(ofs, len(b)) for ofs, b in out] == [(0, 90), (90, 90), (180, 20)]
    assert b"".join(b for _, b in out) == data["00000001.BIN"]


def test_a_file_of_whole_chunks_ends_with_a_zero_length_chunk():
    t = LogTransfer()
    t.request_data(entries(180), 1, 0, 0xFFFFFFFF)
    assert [(ofs, len(b)) for ofs, b in serve(t, {"00000001.BIN": bytes(180)})] == [(0, 90), (90, 90), (180, 0)]


def test_any_offset_and_count_resume_as_arducopter_does():
    data = {"00000001.BIN": bytes(range(256)) * 8}
    t = LogTransfer()
    t.request_data(entries(2048), 1, 1007, 100)
    assert [(ofs, len(b)) for ofs, b in serve(t, data)] == [(1007, 90), (1097, 10)]


def test_a_request_at_the_end_gets_one_empty_chunk():
    t = LogTransfer()
    t.request_data(entries(100), 1, 100, 90)
    assert serve(t, {"00000001.BIN": bytes(100)}) == [(100, b"")]


def test_gap_requests_while_sending_are_queued_not_dropped():
    data = {"00000001.BIN": bytes(range(250)) * 4}
    t = LogTransfer()
    t.request_data(entries(1000), 1, 0, 90)
    t.request_data(entries(1000), 1, 450, 180)
    t.request_data(entries(1000), 1, 900, 90)
    assert [ofs for ofs, _ in serve(t, data)] == [0, 450, 540, 900]


def test_a_request_for_another_log_replaces_the_transfer_and_a_bad_id_ends_it():
    t = LogTransfer()
    t.request_data(entries(500, 500), 1, 0, 0xFFFFFFFF)
    t.request_data(entries(500, 500), 2, 90, 90)
    assert t.next() == Chunk(2, "00000002.BIN", 90, 90)
    t.request_data(entries(500, 500), 3, 0, 90)
    assert not t.busy and t.next() is None


def test_request_end_stops_the_transfer():
    t = LogTransfer()
    t.request_data(entries(500), 1, 0, 0xFFFFFFFF)
    t.end()
    assert t.next() is None


# --- the directory ------------------------------------------------------------------------------
def test_store_numbers_logs_lists_them_oldest_first_and_stamps_the_start(tmp_path):
    store = LogStore(tmp_path, max_files=10, min_free_mb=0)
    a = store.create(1_700_000_000.0)
    a.append(b"abc")
    a.finish()
    b = store.create(1_700_000_100.0)
    b.write_at(400, b"x" * 200)
    assert [(e.id, e.name, e.size, e.time_utc) for e in store.entries()] == [
        (1, "00000001.BIN", 3, 1_700_000_000), (2, "00000002.BIN", 600, 1_700_000_100)]
    assert store.read("00000002.BIN", 400, 90) == b"x" * 90
    assert store.read("00000009.BIN", 0, 90) == b""


def test_rotation_keeps_max_files_and_never_deletes_the_open_log(tmp_path):
    store = LogStore(tmp_path, max_files=3, min_free_mb=0)
    for i in range(5):
        store.create(1_700_000_000.0 + i).finish()
    assert [e.name for e in store.entries()] == ["00000003.BIN", "00000004.BIN", "00000005.BIN"]
    assert store.deleted == 2


def test_rotation_by_free_space_deletes_the_oldest_first_but_not_the_open_log(tmp_path):
    free = {"bytes": 10 * 1024 * 1024}
    store = LogStore(tmp_path, max_files=100, min_free_mb=100, free_bytes=lambda _p: free["bytes"])
    live = store.create(1.0)
    free["bytes"] = 500 * 1024 * 1024
    store.create(2.0).finish()
    free["bytes"] = 10 * 1024 * 1024  # the disk fills up
    third = store.create(3.0)
    names = [e.name for e in store.entries()]
    assert names == ["00000001.BIN", "00000003.BIN"]  # 2 deleted; 1 and 3 are open
    assert not store.make_room()
    live.finish()
    third.finish()


def test_erase_keeps_the_log_being_written(tmp_path):
    store = LogStore(tmp_path, max_files=10, min_free_mb=0)
    store.create(1.0).finish()
    live = store.create(2.0)
    assert store.erase() == 1
    assert [e.name for e in store.entries()] == ["00000002.BIN"]
    live.finish()


def test_a_finished_log_reopened_keeps_its_start_time_and_size(tmp_path):
    store = LogStore(tmp_path, max_files=10, min_free_mb=0)
    f = store.create(1_700_000_000.0)
    f.write_at(0, b"a" * 200)
    f.finish()
    g = store.reopen("00000001.BIN", 1_700_000_000.0)
    g.write_at(200, b"b" * 200)
    g.finish()
    assert os.path.getsize(tmp_path / "00000001.BIN") == 400
    assert store.entries()[0].time_utc == 1_700_000_000
    assert store.reopen("../etc", 0.0) is None


def test_a_late_close_of_the_old_handle_leaves_the_reopened_log_open(tmp_path):
    store = LogStore(tmp_path, max_files=1, min_free_mb=0)
    old = store.create(1.0)
    new = store.reopen("00000001.BIN", 1.0)  # the stream resumed before the old handle was finished
    old.finish()
    assert store.is_open("00000001.BIN")
    store.create(2.0).finish()  # max_files 1: rotation must not delete the log being written
    assert (tmp_path / "00000001.BIN").exists()
    new.finish()


# --- LOG_DATA's fast packing --------------------------------------------------------------------
@pytest.mark.parametrize("data", [bytes(range(90)), b"abc", b"", bytes(89) + b"\x01", b"\x01" + bytes(89)])
@pytest.mark.parametrize(("v1", "signed"), [(False, False), (True, False), (False, True)])
def test_fast_log_data_packs_the_bytes_pymavlink_packs(data, v1, signed):
    def mav():
        m = M.MAVLink(None, srcSystem=7, srcComponent=1)
        m.seq = 200
        if signed:
            m.signing.secret_key, m.signing.link_id, m.signing.timestamp = bytes(32), 3, 1000
            m.signing.sign_outgoing = True
        return m

    slow = M.MAVLink_log_data_message(5, 123_456, len(data), data.ljust(90, b"\0")).pack(mav(), force_mavlink1=v1)
    assert LogData(5, 123_456, len(data), data).pack(mav(), force_mavlink1=v1) == slow


# --- repeated requests and growing logs (issue 27) ----------------------------------------------

def listed(t: LogTransfer, sizes: tuple[int, ...]) -> list[LogEntry]:
    e = entries(*sizes)
    t.request_list(e, 0, 0xFFFF)
    serve(t, {})
    return e


def test_overlapping_and_repeated_requests_are_merged_not_sent_twice():
    t = LogTransfer()
    e = entries(10_000)
    for ofs, count in [(0, 900), (450, 900), (1350, 90), (0, 90)]:
        t.request_data(e, 1, ofs, count)
    out = serve(t, {"00000001.BIN": bytes(10_000)})
    assert [ofs for ofs, _ in out] == list(range(0, 1440, 90)), "each chunk once, in order"


def test_a_log_that_grew_since_it_was_listed_is_served_up_to_its_listed_size():
    t = LogTransfer()
    e = listed(t, (1000,))
    grown = [LogEntry(1, e[0].name, 5000, e[0].time_utc)]
    t.request_data(grown, 1, 0, COUNT)
    out = serve(t, {e[0].name: bytes(5000)})
    assert sum(len(b) for _, b in out) == 1000 and len(out[-1][1]) < 90


def test_a_listed_log_of_whole_chunks_still_ends_on_an_empty_chunk():
    t = LogTransfer()
    e = listed(t, (180,))
    t.request_data(e, 1, 0, COUNT)
    assert [(ofs, len(b)) for ofs, b in serve(t, {e[0].name: bytes(180)})] == [(0, 90), (90, 90), (180, 0)]
