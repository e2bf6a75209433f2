"""The FTP server core as a specification (REFERENCE.md section 8, SPEC.md FTP): every opcode,
the NAK codes, sessions, retries, the idle timeout and burst reads, with a float clock."""

from __future__ import annotations

import errno
import itertools
import os
import zlib

import pytest
from ftp_helpers import Gcs, errno_of, is_ack, make_server, nak_code

from gcsd.vehicle.ftp.burst import (
    ADD_PPS,
    BURST_PACKETS,
    HOLD_PACKETS,
    MAX_PPS,
    MIN_PPS,
    PROBE_PACKETS,
    SLACK_S,
    START_PPS,
)
from gcsd.vehicle.ftp.protocol import DATA_MAX, Nak, Op, Payload, crc32_ardupilot
from gcsd.vehicle.ftp.server import MAX_SESSIONS, SESSION_IDLE_S


@pytest.fixture
def root(tmp_path):
    r = tmp_path / "root"
    r.mkdir()
    return r


@pytest.fixture
def server(root):
    return make_server(root, max_file_bytes=100_000)


@pytest.fixture
def gcs(server):
    return Gcs(server)


def opened(gcs: Gcs, name: bytes, now: float = 0.0) -> int:
    reply = gcs.one(Op.OPEN_FILE_RO, name, now=now)
    assert is_ack(reply), reply
    return int.from_bytes(reply.data[:4], "little")


# --- framing and addressing ------------------------------------------------------------------


def test_none_is_acked_with_seq_plus_one_same_session_and_req_opcode(gcs):
    reply = gcs.one(Op.NONE, seq=41)
    got = (reply.opcode, reply.seq, reply.session, reply.req_opcode, reply.size)
    assert got == (Op.ACK, 42, 1, Op.NONE, 0)


def test_reply_goes_to_the_requester_on_its_channel(server):
    other = Gcs(server, sysid=250, compid=1, channel=3)
    assert is_ack(other.one(Op.NONE))  # the helper checks channel and target of every reply


def test_acks_and_naks_from_a_client_get_no_answer(gcs):
    assert gcs.request(Op.ACK) == []
    assert gcs.request(Op.NAK) == []


def test_reply_seq_wraps_at_65536(gcs):
    assert gcs.one(Op.NONE, seq=65535).seq == 0


def test_request_size_above_239_is_invalid_data_size(gcs):
    assert nak_code(gcs.one(Op.LIST_DIRECTORY, b"/", size=240)) == Nak.INVALID_DATA_SIZE


@pytest.mark.parametrize("size", [0, 1, 4, 10])
def test_path_size_other_than_its_length_or_length_plus_one_is_invalid_data_size(gcs, size):
    assert nak_code(gcs.one(Op.LIST_DIRECTORY, b"/a", size=size)) == Nak.INVALID_DATA_SIZE


def test_path_size_may_count_a_trailing_nul(gcs, root):
    (root / "a").mkdir()
    assert nak_code(gcs.one(Op.LIST_DIRECTORY, b"a\0", size=2)) == Nak.EOF  # accepted: an empty dir


@pytest.mark.parametrize("opcode", [16, 17, 99, 127])
def test_unknown_opcodes_are_unknown_command(gcs, opcode):
    reply = gcs.one(opcode)
    assert nak_code(reply) == Nak.UNKNOWN_COMMAND and reply.size == 1


# --- ListDirectory ---------------------------------------------------------------------------


def test_list_directory_gives_sorted_files_with_sizes_and_directories(gcs, root):
    (root / "b.bin").write_bytes(b"x" * 1234)
    (root / "a.txt").write_bytes(b"")
    (root / "sub").mkdir()
    reply = gcs.one(Op.LIST_DIRECTORY, b"/")
    assert is_ack(reply) and reply.offset == 0
    entries = reply.data[:reply.size].split(b"\0")[:-1]
    assert entries == [b"Fa.txt\t0", b"Fb.bin\t1234", b"Dsub"]
    assert reply.data[reply.size:] == bytes(DATA_MAX - reply.size)


def test_list_directory_of_root_also_lists_the_virtual_directories(root, tmp_path):
    from test_ftp_parampck import FakeParams

    gcs = Gcs(make_server(root, params=FakeParams([])))
    entries = gcs.one(Op.LIST_DIRECTORY, b"/").data.split(b"\0")
    assert b"D@PARAM" in entries


def test_list_directory_pages_by_entry_offset_until_eof(gcs, root):
    names = [f"file-with-a-long-name-{i:03d}.dat" for i in range(40)]
    for name in names:
        (root / name).write_bytes(b"1")
    seen, offset = [], 0
    while True:
        reply = gcs.one(Op.LIST_DIRECTORY, b"/", offset=offset)
        if nak_code(reply) == Nak.EOF:
            break
        assert reply.offset == offset and reply.size < DATA_MAX
        page = [e[1:].split(b"\t")[0].decode() for e in reply.data[:reply.size].split(b"\0")[:-1]]
        assert page
        seen += page
        offset += len(page)
    assert seen == names


def test_list_directory_trailing_slash_is_ignored(gcs, root):
    (root / "d").mkdir()
    (root / "d" / "f").write_bytes(b"12")
    assert gcs.one(Op.LIST_DIRECTORY, b"d/").data.startswith(b"Ff\t2\0")


def test_list_directory_of_a_missing_directory_is_file_not_found(gcs):
    assert nak_code(gcs.one(Op.LIST_DIRECTORY, b"/nope")) == Nak.FILE_NOT_FOUND


def test_list_directory_of_a_file_is_fail_errno_enotdir(gcs, root):
    (root / "f").write_bytes(b"")
    reply = gcs.one(Op.LIST_DIRECTORY, b"f")
    assert nak_code(reply) == Nak.FAIL_ERRNO and errno_of(reply) == errno.ENOTDIR and reply.size == 2


# --- reading ---------------------------------------------------------------------------------


def test_open_file_ro_acks_with_the_exact_size(gcs, root):
    (root / "f").write_bytes(b"x" * 100_001)
    reply = gcs.one(Op.OPEN_FILE_RO, b"/f")
    assert is_ack(reply) and reply.size == 4 and int.from_bytes(reply.data[:4], "little") == 100_001


def test_open_file_ro_of_a_missing_file_is_file_not_found(gcs):
    assert nak_code(gcs.one(Op.OPEN_FILE_RO, b"missing")) == Nak.FILE_NOT_FOUND


def test_open_file_ro_of_a_directory_is_fail_errno_eisdir(gcs, root):
    (root / "d").mkdir()
    assert errno_of(gcs.one(Op.OPEN_FILE_RO, b"d")) == errno.EISDIR


def test_one_file_per_session_second_open_is_fail(gcs, root):
    (root / "f").write_bytes(b"1")
    opened(gcs, b"f")
    assert nak_code(gcs.one(Op.OPEN_FILE_RO, b"f", now=1.0)) == Nak.FAIL


def test_a_file_idle_for_3_s_is_closed_by_a_new_open_in_the_same_session(gcs, root):
    (root / "f").write_bytes(b"1")
    (root / "g").write_bytes(b"22")
    opened(gcs, b"f", now=0.0)
    assert opened(gcs, b"g", now=3.5) == 2


def test_read_file_returns_bytes_at_offset_up_to_the_requested_size(gcs, root):
    data = os.urandom(1000)
    (root / "f").write_bytes(data)
    opened(gcs, b"f")
    reply = gcs.one(Op.READ_FILE, size=100, offset=500)
    assert is_ack(reply) and reply.offset == 500 and reply.data[:reply.size] == data[500:600]
    reply = gcs.one(Op.READ_FILE, size=239, offset=900)
    assert reply.size == 100 and reply.data[:100] == data[900:]


def test_read_file_past_the_end_is_eof(gcs, root):
    (root / "f").write_bytes(b"abc")
    opened(gcs, b"f")
    assert nak_code(gcs.one(Op.READ_FILE, size=10, offset=3)) == Nak.EOF


def test_read_file_without_an_open_file_is_file_not_found(gcs):
    assert nak_code(gcs.one(Op.READ_FILE, size=10)) == Nak.FILE_NOT_FOUND


def test_read_file_on_a_file_opened_for_writing_is_fail(gcs):
    assert is_ack(gcs.one(Op.CREATE_FILE, b"new"))
    assert nak_code(gcs.one(Op.READ_FILE, size=10)) == Nak.FAIL


# --- writing ---------------------------------------------------------------------------------


def test_create_file_truncates_and_write_file_writes_at_the_offset(gcs, root):
    (root / "f").write_bytes(b"old content that is long")
    assert is_ack(gcs.one(Op.CREATE_FILE, b"f"))
    reply = gcs.one(Op.WRITE_FILE, b"world", offset=6)
    assert is_ack(reply) and reply.offset == 6 and reply.size == 0
    assert is_ack(gcs.one(Op.WRITE_FILE, b"hello ", offset=0))
    assert is_ack(gcs.one(Op.TERMINATE_SESSION))
    assert (root / "f").read_bytes() == b"hello world"


def test_open_file_wo_keeps_the_content_and_creates_a_missing_file(gcs, root):
    (root / "f").write_bytes(b"0123456789")
    assert is_ack(gcs.one(Op.OPEN_FILE_WO, b"f"))
    assert is_ack(gcs.one(Op.WRITE_FILE, b"ab", offset=2))
    gcs.one(Op.TERMINATE_SESSION)
    assert (root / "f").read_bytes() == b"01ab456789"
    assert is_ack(gcs.one(Op.OPEN_FILE_WO, b"g"))
    assert (root / "g").exists()


def test_create_file_when_the_file_exists_as_a_directory_is_fail_errno(gcs, root):
    (root / "d").mkdir()
    assert nak_code(gcs.one(Op.CREATE_FILE, b"d")) == Nak.FAIL_ERRNO


def test_create_file_in_a_missing_directory_is_file_not_found(gcs):
    assert nak_code(gcs.one(Op.CREATE_FILE, b"no/such/dir/f")) == Nak.FILE_NOT_FOUND


def test_write_file_without_an_open_file_is_file_not_found(gcs):
    assert nak_code(gcs.one(Op.WRITE_FILE, b"x")) == Nak.FILE_NOT_FOUND


def test_write_file_on_a_file_opened_for_reading_is_fail(gcs, root):
    (root / "f").write_bytes(b"1")
    opened(gcs, b"f")
    assert nak_code(gcs.one(Op.WRITE_FILE, b"x")) == Nak.FAIL
    assert (root / "f").read_bytes() == b"1"


def test_write_beyond_the_size_limit_is_fail_errno_efbig_and_writes_nothing(gcs, root):
    assert is_ack(gcs.one(Op.CREATE_FILE, b"big"))
    reply = gcs.one(Op.WRITE_FILE, b"x" * 10, offset=100_000 - 5)
    assert errno_of(reply) == errno.EFBIG
    assert is_ack(gcs.one(Op.WRITE_FILE, b"x" * 5, offset=100_000 - 5))
    gcs.one(Op.TERMINATE_SESSION)
    assert (root / "big").stat().st_size == 100_000


def test_truncate_file_sets_the_length_to_the_offset(gcs, root):
    (root / "f").write_bytes(b"0123456789")
    assert is_ack(gcs.one(Op.TRUNCATE_FILE, b"f", offset=4))
    assert (root / "f").read_bytes() == b"0123"
    assert errno_of(gcs.one(Op.TRUNCATE_FILE, b"f", offset=100_001)) == errno.EFBIG
    assert nak_code(gcs.one(Op.TRUNCATE_FILE, b"missing", offset=0)) == Nak.FILE_NOT_FOUND


# --- removing, directories, renaming ---------------------------------------------------------


def test_remove_file_removes_a_file(gcs, root):
    (root / "f").write_bytes(b"1")
    assert is_ack(gcs.one(Op.REMOVE_FILE, b"f"))
    assert not (root / "f").exists()
    assert nak_code(gcs.one(Op.REMOVE_FILE, b"f")) == Nak.FILE_NOT_FOUND


def test_remove_file_on_a_directory_is_fail_errno_eisdir(gcs, root):
    (root / "d").mkdir()
    assert errno_of(gcs.one(Op.REMOVE_FILE, b"d")) == errno.EISDIR
    assert (root / "d").is_dir()


def test_create_directory_then_it_exists(gcs, root):
    assert is_ack(gcs.one(Op.CREATE_DIRECTORY, b"logs"))
    assert (root / "logs").is_dir()
    assert nak_code(gcs.one(Op.CREATE_DIRECTORY, b"logs")) == Nak.FILE_EXISTS


def test_remove_directory_removes_only_an_empty_directory(gcs, root):
    (root / "d").mkdir()
    (root / "d" / "f").write_bytes(b"")
    assert errno_of(gcs.one(Op.REMOVE_DIRECTORY, b"d")) == errno.ENOTEMPTY
    (root / "d" / "f").unlink()
    assert is_ack(gcs.one(Op.REMOVE_DIRECTORY, b"d"))
    assert not (root / "d").exists()
    (root / "f").write_bytes(b"")
    assert errno_of(gcs.one(Op.REMOVE_DIRECTORY, b"f")) == errno.ENOTDIR


def test_the_root_itself_cannot_be_removed(gcs, root):
    assert nak_code(gcs.one(Op.REMOVE_DIRECTORY, b"/")) == Nak.FAIL
    assert root.is_dir()


def test_rename_moves_a_file(gcs, root):
    (root / "a").write_bytes(b"1")
    (root / "d").mkdir()
    assert is_ack(gcs.one(Op.RENAME, b"a\0d/b"))
    assert (root / "d" / "b").read_bytes() == b"1" and not (root / "a").exists()


def test_rename_accepts_a_trailing_nul_in_the_size(gcs, root):
    (root / "a").write_bytes(b"1")
    assert is_ack(gcs.one(Op.RENAME, b"a\0b\0", size=4))


@pytest.mark.parametrize("data,size", [(b"a", 1), (b"a\0", 2), (b"\0b", 2), (b"a\0b", 5)])
def test_rename_with_a_malformed_pair_is_invalid_data_size(gcs, root, data, size):
    (root / "a").write_bytes(b"1")
    assert nak_code(gcs.one(Op.RENAME, data, size=size)) == Nak.INVALID_DATA_SIZE
    assert (root / "a").exists()


def test_rename_of_a_missing_file_is_file_not_found(gcs):
    assert nak_code(gcs.one(Op.RENAME, b"a\0b")) == Nak.FILE_NOT_FOUND


# --- CRC32 -----------------------------------------------------------------------------------


def test_crc32_is_ardupilots_seed_0_without_final_xor(gcs, root):
    data = os.urandom(5000)
    (root / "f").write_bytes(data)
    reply = gcs.one(Op.CALC_FILE_CRC32, b"f")
    assert is_ack(reply) and reply.size == 4
    crc = int.from_bytes(reply.data[:4], "little")
    assert crc == (~zlib.crc32(data, 0xFFFFFFFF)) & 0xFFFFFFFF == crc32_ardupilot(data)
    assert crc32_ardupilot(b"123456789") == 0x2DFD2D88  # seed 0, no final XOR


def test_crc32_of_a_big_file_is_computed_in_slices_and_answered_from_the_send_pass(gcs, root):
    data = os.urandom(3 * 1024 * 1024 + 7)
    (root / "big").write_bytes(data)
    assert gcs.request(Op.CALC_FILE_CRC32, b"big") == []
    assert gcs.server.has_work(0) and gcs.server.next_deadline(0.0) == 0.0
    assert gcs.resend() == []  # the repeat of a running computation is not started again
    replies = []
    for _ in range(10):
        replies += gcs.pump()
    [reply] = replies
    assert int.from_bytes(reply.data[:4], "little") == crc32_ardupilot(data)
    assert gcs.resend() == [reply]  # and a later repeat gets the stored answer


def test_crc32_of_a_missing_file_is_file_not_found(gcs):
    assert nak_code(gcs.one(Op.CALC_FILE_CRC32, b"missing")) == Nak.FILE_NOT_FOUND


# --- BurstReadFile ---------------------------------------------------------------------------


def distinct(packets):
    """The burst without the second copy of each burst_complete packet."""
    out = []
    for p in packets:
        if out and p == out[-1]:
            assert p.burst_complete == 1, p
            continue
        out.append(p)
    return out


def test_burst_honours_the_requested_block_size_and_ends_short_then_eof(gcs, root):
    data = os.urandom(1000)
    (root / "f").write_bytes(data)
    opened(gcs, b"f")
    packets = distinct(gcs.burst(block=80))
    assert [p.offset for p in packets[:-1]] == list(range(0, 1000, 80))
    assert all(p.size == 80 and p.burst_complete == 0 for p in packets[:-2])
    short, eof = packets[-2:]
    assert (short.size, short.burst_complete) == (40, 1)
    assert (nak_code(eof), eof.offset, eof.burst_complete) == (Nak.EOF, 1000, 1)
    assert b"".join(p.data[:p.size] for p in packets[:-1]) == data
    assert all(p.req_opcode == Op.BURST_READ_FILE for p in packets)
    assert [p.seq for p in packets] == list(range(1 + 1, 1 + 1 + len(packets)))  # request seq was 1


def test_every_burst_complete_packet_is_sent_twice_with_the_same_seq(gcs, root):
    (root / "f").write_bytes(b"x" * 100)
    opened(gcs, b"f")
    packets = gcs.burst(block=80)
    assert [(p.opcode, p.offset, p.burst_complete) for p in packets] == [
        (Op.ACK, 0, 0), (Op.ACK, 80, 1), (Op.ACK, 80, 1), (Op.NAK, 100, 1), (Op.NAK, 100, 1)]
    assert packets[1] == packets[2] and packets[3] == packets[4]


def test_burst_block_size_0_means_239(gcs, root):
    (root / "f").write_bytes(b"x" * 500)
    opened(gcs, b"f")
    packets = distinct(gcs.burst(block=0))
    assert [p.size for p in packets[:-1]] == [239, 239, 22]


def test_burst_reading_exactly_to_the_end_sends_a_full_chunk_then_eof(gcs, root):
    (root / "f").write_bytes(b"x" * 160)
    opened(gcs, b"f")
    packets = distinct(gcs.burst(block=80))
    assert [(p.opcode, p.size, p.burst_complete) for p in packets] == [
        (Op.ACK, 80, 0), (Op.ACK, 80, 0), (Op.NAK, 1, 1)]
    assert packets[-1].offset == 160


def test_burst_starts_at_the_requested_offset(gcs, root):
    data = os.urandom(300)
    (root / "f").write_bytes(data)
    opened(gcs, b"f")
    packets = gcs.burst(offset=250, block=100)
    assert packets[0].offset == 250 and packets[0].data[:50] == data[250:]


def test_burst_ends_after_burst_packets_with_burst_complete(gcs, root):
    (root / "f").write_bytes(b"y" * (BURST_PACKETS * 10 + 100))
    opened(gcs, b"f")
    packets = distinct(gcs.burst(block=10))
    assert len(packets) == BURST_PACKETS
    assert packets[-1].burst_complete == 1 and all(p.burst_complete == 0 for p in packets[:-1])
    assert not gcs.server.has_work(0)


def test_pump_gives_at_most_the_packets_asked_for(gcs, root):
    (root / "f").write_bytes(b"z" * 10_000)
    opened(gcs, b"f")
    assert gcs.request(Op.BURST_READ_FILE, size=100) == []
    assert len(gcs.pump(max_packets=7)) == 7
    assert gcs.server.has_work(0)
    assert gcs.pump(max_packets=10_000)[0].offset == 700


def intervals(gcs: Gcs, count: int, now: float = 0.0) -> list[float]:
    """The send times of the next `count` burst packets, pumped one at a time at their due time."""
    times = []
    for _ in range(count):
        assert len(gcs.server.pump(0, now, 1)) == 1
        times.append(now)
        now = gcs.server.next_deadline(now, 0)
    return [b - a for a, b in itertools.pairwise(times)]


def test_burst_packets_are_paced_from_the_start_rate(gcs, root):
    (root / "f").write_bytes(b"p" * 100_000)
    opened(gcs, b"f")
    assert gcs.request(Op.BURST_READ_FILE, size=100) == []
    early = gcs.server.pump(0, 0.0, 10_000)
    assert abs(len(early) - SLACK_S * START_PPS) <= 1  # what is due within the slack
    assert gcs.server.next_deadline(0.0, 0) == pytest.approx(len(early) / START_PPS)
    assert gcs.server.pump(0, 0.0, 10_000) == []  # nothing more until then


def test_the_rate_grows_by_500_per_s_after_100_packets_without_loss(gcs, root):
    (root / "f").write_bytes(b"p" * 100_000)
    opened(gcs, b"f")
    gcs.request(Op.BURST_READ_FILE, size=100)
    gaps = intervals(gcs, PROBE_PACKETS + 3)
    assert gaps[0] == pytest.approx(1 / START_PPS)
    assert gaps[-1] == pytest.approx(1 / (START_PPS + ADD_PPS))


def test_a_request_for_an_offset_the_burst_passed_halves_the_rate(gcs, root):
    (root / "f").write_bytes(b"p" * 100_000)
    opened(gcs, b"f")
    gcs.request(Op.BURST_READ_FILE, size=100)
    intervals(gcs, HOLD_PACKETS + 1)
    assert is_ack(gcs.one(Op.READ_FILE, size=100, offset=1000))  # a gap the client wants again
    assert is_ack(gcs.one(Op.READ_FILE, size=100, offset=1100))  # same batch: no second halving
    now = gcs.server.next_deadline(0.0, 0)
    assert intervals(gcs, 3, now)[-1] == pytest.approx(2 / START_PPS)


def test_the_rate_falls_no_lower_than_its_minimum(gcs, root):
    (root / "f").write_bytes(b"p" * 1_000_000)
    opened(gcs, b"f")
    gcs.request(Op.BURST_READ_FILE, size=100)
    now = 0.0
    for _ in range(12):
        intervals(gcs, HOLD_PACKETS, now)
        now = gcs.server.next_deadline(now, 0)
        gcs.one(Op.READ_FILE, size=100, offset=0, now=now)
    assert intervals(gcs, 3, gcs.server.next_deadline(now, 0))[-1] == pytest.approx(1 / MIN_PPS)


def test_the_rate_grows_no_higher_than_its_maximum_and_carries_over_to_the_next_burst(gcs, root):
    (root / "f").write_bytes(b"p" * 2_000_000)
    opened(gcs, b"f")
    gcs.request(Op.BURST_READ_FILE, size=100)
    now = 0.0
    for offset in range(0, 1_000_000, BURST_PACKETS * 100):
        gcs.request(Op.BURST_READ_FILE, size=100, offset=offset, now=now)
        assert len(gcs.pump(now)) == BURST_PACKETS + 1  # the last one twice
        now += 1.0
    gcs.request(Op.BURST_READ_FILE, size=100, offset=1_000_000, now=now)
    assert intervals(gcs, 3, now)[-1] == pytest.approx(1 / MAX_PPS)


def test_burst_without_an_open_file_is_file_not_found(gcs):
    assert nak_code(gcs.one(Op.BURST_READ_FILE, size=80)) == Nak.FILE_NOT_FOUND


def test_a_repeated_burst_request_is_ignored_while_it_runs_and_runs_again_when_done(gcs, root):
    (root / "f").write_bytes(b"q" * 1000)
    opened(gcs, b"f")
    assert gcs.request(Op.BURST_READ_FILE, size=100) == []
    first = gcs.pump(max_packets=3)
    assert gcs.resend() == []
    rest = gcs.pump()
    assert [p.offset for p in distinct(first + rest)][:-1] == list(range(0, 1000, 100))
    assert gcs.resend() == []
    assert [p.offset for p in gcs.pump()][:2] == [0, 100]


def test_a_new_burst_request_replaces_the_running_one(gcs, root):
    (root / "f").write_bytes(b"q" * 1000)
    opened(gcs, b"f")
    gcs.request(Op.BURST_READ_FILE, size=100)
    gcs.pump(max_packets=2)
    gcs.request(Op.BURST_READ_FILE, size=100, offset=800)
    assert [p.offset for p in distinct(gcs.pump())] == [800, 900, 1000]


def test_read_file_works_alongside_a_running_burst(gcs, root):
    data = os.urandom(1000)
    (root / "f").write_bytes(data)
    opened(gcs, b"f")
    gcs.request(Op.BURST_READ_FILE, size=100)
    gcs.pump(max_packets=2)
    assert gcs.one(Op.READ_FILE, size=50, offset=10).data[:50] == data[10:60]
    assert gcs.pump()[0].offset == 200


# --- retries -----------------------------------------------------------------------------------


def test_a_repeated_request_gets_the_same_reply_without_running_again(gcs, root):
    (root / "f").write_bytes(b"1")
    first = gcs.one(Op.REMOVE_FILE, b"f")
    assert is_ack(first)
    assert gcs.resend() == [first]  # not FileNotFound: the removal is not done twice


def test_a_repeated_create_file_does_not_truncate_what_was_written(gcs, root):
    assert is_ack(gcs.one(Op.CREATE_FILE, b"f"))
    create_raw = gcs.last_raw
    gcs.one(Op.WRITE_FILE, b"data")
    gcs.last_raw = create_raw  # a late duplicate of the CreateFile, after a write
    assert nak_code(gcs.resend()[0]) == Nak.FAIL  # the session's file is open: not truncated again
    gcs.one(Op.TERMINATE_SESSION)
    assert (root / "f").read_bytes() == b"data"


def test_a_different_request_with_the_same_seq_is_executed(gcs, root):
    (root / "a").write_bytes(b"1")
    (root / "b").write_bytes(b"2")
    assert is_ack(gcs.one(Op.REMOVE_FILE, b"a", seq=7))
    assert is_ack(gcs.one(Op.REMOVE_FILE, b"b", seq=7))
    assert not (root / "b").exists()


def test_a_repeated_terminate_gets_the_same_answer(gcs, root):
    (root / "f").write_bytes(b"1")
    opened(gcs, b"f")
    reply = gcs.one(Op.TERMINATE_SESSION)
    assert gcs.resend() == [reply]


# --- sessions --------------------------------------------------------------------------------


def test_five_sessions_across_ground_stations_then_no_sessions_available(server, root):
    (root / "f").write_bytes(b"1")
    clients = [Gcs(server, sysid=200 + i, session=1) for i in range(MAX_SESSIONS)]
    for c in clients:
        opened(c, b"f")
    sixth = Gcs(server, sysid=250)
    reply = sixth.one(Op.OPEN_FILE_RO, b"f", now=10.0)
    assert nak_code(reply) == Nak.NO_SESSIONS_AVAILABLE
    assert is_ack(clients[0].one(Op.TERMINATE_SESSION, now=10.0))
    assert opened(sixth, b"f", now=10.0) == 1


def test_sessions_are_keyed_by_sender_and_channel_as_well_as_number(server, root):
    (root / "a").write_bytes(b"a" * 10)
    (root / "b").write_bytes(b"b" * 20)
    one, two = Gcs(server, sysid=255, session=0), Gcs(server, sysid=254, session=0)
    three = Gcs(server, sysid=255, session=0, channel=1)
    assert opened(one, b"a") == 10 and opened(two, b"b") == 20 and opened(three, b"b") == 20
    assert one.one(Op.READ_FILE, size=5).data[:5] == b"aaaaa"
    assert two.one(Op.READ_FILE, size=5).data[:5] == b"bbbbb"


def test_an_idle_session_without_a_file_gives_its_slot_up_after_3_s(server, root):
    clients = [Gcs(server, sysid=200 + i) for i in range(MAX_SESSIONS)]
    for c in clients:
        assert is_ack(c.one(Op.NONE, now=0.0))
    late = Gcs(server, sysid=250)
    assert nak_code(late.one(Op.NONE, now=1.0)) == Nak.NO_SESSIONS_AVAILABLE
    assert is_ack(late.one(Op.NONE, now=3.0))
    assert server.session_count() == MAX_SESSIONS


def test_a_session_holding_a_file_keeps_its_slot_until_the_idle_timeout(server, root):
    (root / "f").write_bytes(b"1")
    clients = [Gcs(server, sysid=200 + i) for i in range(MAX_SESSIONS)]
    for c in clients:
        opened(c, b"f")
    late = Gcs(server, sysid=250)
    assert nak_code(late.one(Op.NONE, now=SESSION_IDLE_S - 0.1)) == Nak.NO_SESSIONS_AVAILABLE
    assert is_ack(late.one(Op.NONE, now=SESSION_IDLE_S))


def test_an_idle_session_is_closed_after_30_s(gcs, root):
    (root / "f").write_bytes(b"abc")
    opened(gcs, b"f", now=0.0)
    assert is_ack(gcs.one(Op.READ_FILE, size=3, now=SESSION_IDLE_S - 0.1))
    assert gcs.server.next_deadline(SESSION_IDLE_S) == pytest.approx(2 * SESSION_IDLE_S - 0.1)
    assert nak_code(gcs.one(Op.READ_FILE, size=3, now=2 * SESSION_IDLE_S)) == Nak.FILE_NOT_FOUND


def test_terminate_session_closes_the_file(gcs, root):
    (root / "f").write_bytes(b"abc")
    opened(gcs, b"f")
    reply = gcs.one(Op.TERMINATE_SESSION)
    assert is_ack(reply) and reply.req_opcode == Op.TERMINATE_SESSION
    assert nak_code(gcs.one(Op.READ_FILE, size=3)) == Nak.FILE_NOT_FOUND
    assert gcs.server.session_count() == 1  # the ReadFile made a fresh, empty one


def test_terminate_of_an_unknown_session_is_acked(gcs):
    assert is_ack(gcs.one(Op.TERMINATE_SESSION, session=99))


def test_reset_sessions_closes_only_the_senders_sessions(server, root):
    (root / "f").write_bytes(b"abc")
    mine_a, mine_b = Gcs(server, sysid=255, session=1), Gcs(server, sysid=255, session=2)
    theirs = Gcs(server, sysid=254, session=1)
    for c in (mine_a, mine_b, theirs):
        opened(c, b"f")
    assert is_ack(mine_a.one(Op.RESET_SESSIONS))
    assert nak_code(mine_b.one(Op.READ_FILE, size=3)) == Nak.FILE_NOT_FOUND
    assert is_ack(theirs.one(Op.READ_FILE, size=3))


def test_next_deadline_is_none_without_sessions(server):
    assert server.next_deadline(0.0) is None


def test_payload_round_trips_and_pads_data(gcs):
    p = Payload(513, 2, Op.WRITE_FILE, 3, 0, 0, 70000, b"abc")
    raw = p.pack()
    assert len(raw) == 251 and Payload.unpack(raw) == Payload(513, 2, Op.WRITE_FILE, 3, 0, 0, 70000,
                                                              b"abc" + bytes(236))
    assert Payload.unpack(raw[:15]).data[:3] == b"abc"  # MAVLink2 trimmed the zeros
