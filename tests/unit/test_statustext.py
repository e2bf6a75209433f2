"""STATUSTEXT chunking and the queue (GCS::send_textv / service_statustext)."""

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.services.statustext import QUEUE_LEN, StatusTextQueue, chunk_text

INFO = M.MAV_SEVERITY_INFO


def texts(msgs):
    return [(m.id, m.chunk_seq, m.text) for m in msgs]


def test_short_text_is_one_message_with_id_zero():
    [m] = chunk_text("Arming motors", INFO, 9)
    assert (m.id, m.chunk_seq) == (0, 0)


def test_fifty_byte_text_is_one_message():
    assert len(chunk_text("x" * 50, INFO, 9)) == 1


def test_long_text_is_chunked_with_a_shared_id():
    msgs = chunk_text("a" * 50 + "b" * 50 + "c" * 10, INFO, 9)
    assert [(m.id, m.chunk_seq, len(m.text)) for m in msgs] == [(9, 0, 50), (9, 1, 50), (9, 2, 10)]


def test_exact_multiple_of_fifty_ends_with_an_empty_chunk():
    msgs = chunk_text("a" * 100, INFO, 4)
    assert [(m.chunk_seq, len(m.text)) for m in msgs] == [(0, 50), (1, 50), (2, 0)]


def test_text_is_capped_at_250_bytes():
    assert sum(len(m.text) for m in chunk_text("z" * 400, INFO, 1)) == 250


def test_queue_sends_each_entry_once_per_channel():
    q = StatusTextQueue()
    q.add(INFO, "hello", {0, 1}, now=0.0)
    sent = {0: [], 1: []}
    q.drain(0, 0.1, lambda m: sent[0].append(m) or True)
    q.drain(0, 0.2, lambda m: sent[0].append(m) or True)
    q.drain(1, 0.3, lambda m: sent[1].append(m) or True)
    assert [len(v) for v in sent.values()] == [1, 1]
    assert not q.pending_for(0) and not q.pending_for(1)


def test_queue_keeps_an_entry_when_the_link_is_full():
    q = StatusTextQueue()
    q.add(INFO, "hello", {0}, now=0.0)
    assert q.drain(0, 0.1, lambda m: False) is False
    assert q.pending_for(0)


def test_queue_drops_oldest_beyond_capacity_and_counts_it():
    q = StatusTextQueue()
    for i in range(QUEUE_LEN + 5):
        q.add(INFO, f"t{i}", {0}, now=0.0)
    got = []
    q.drain(0, 0.1, lambda m: got.append(m.text) or True)
    assert len(got) == QUEUE_LEN and got[0] == "t5" and q.dropped == 5


def test_entries_older_than_five_seconds_are_dropped():
    q = StatusTextQueue()
    q.add(INFO, "stale", {0}, now=0.0)
    got = []
    q.drain(0, 6.0, lambda m: got.append(m) or True)
    assert got == []


def test_chunk_ids_skip_zero_when_the_counter_wraps():
    q = StatusTextQueue()
    ids = set()
    for _ in range(0x10001):
        q.add(INFO, "y" * 60, {0}, now=0.0)
        q.drain(0, 0.0, lambda m: ids.add(m.id) or True)
    assert 0 not in ids
