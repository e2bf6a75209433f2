"""The capture core against a flight controller that behaves as AP_Logger_MAVLink, on a fake
clock: lost blocks, a pause, a restarted sequence; the files are the flight controller's log
byte for byte, and DFReader reads them."""

from __future__ import annotations

import random

import pytest
from pymavlink import DFReader

from fake_logger_fc import START, STOP, FakeLoggerFC
from gcsd.payloads.logs.capture import ACK, NACK, SEQ_START, Capture, Close, Open, Status, Write
from gcsd.payloads.logs.simlog import FlightRecorder
from gcsd.vehicle.sim.state import VehicleState

ME = (191, 191)
LOG = 155
CH = 0
TICK_S = 0.005


class Harness:
    """One capture core, one fake flight controller, a lossy link between them, a fake clock."""

    def __init__(self, loss: float = 0.0, ack_loss: float = 0.0, seed: int = 1) -> None:
        self.capture = Capture(*ME)
        self.fc = FakeLoggerFC()
        self.rng = random.Random(seed)
        self.loss, self.ack_loss = loss, ack_loss
        self.now = 0.0
        self.files: dict[int, bytearray] = {}
        self.order: list[int] = []
        self.closed: set[int] = set()
        self.sent: list[Status] = []
        self.apply(self.capture.handle_heartbeat(CH, 1, 1, 3, self.now))

    def apply(self, effects) -> None:
        for e in effects:
            if isinstance(e, Open):
                self.files[e.key] = bytearray()
                self.order.append(e.key)
            elif isinstance(e, Write):
                f = self.files[e.key]
                if len(f) < e.offset + len(e.data):
                    f.extend(bytes(e.offset + len(e.data) - len(f)))
                f[e.offset:e.offset + len(e.data)] = e.data
                self.closed.discard(e.key)
            elif isinstance(e, Close):
                self.closed.add(e.key)
            elif isinstance(e, Status):
                self.sent.append(e)
                assert (e.channel, e.sysid) == (CH, 1)
                if self.rng.random() >= self.ack_loss:
                    self.fc.handle_status(e.seqno, e.status, ME, self.now)

    def run(self, seconds: float, produce_bytes_per_s: float = 0.0, source=None) -> None:
        end = self.now + seconds
        while self.now < end:
            self.now += TICK_S
            if source is not None and produce_bytes_per_s:
                self.fc.write(source.take(int(produce_bytes_per_s * TICK_S)))
            for seqno, data in self.fc.poll(self.now):
                if self.rng.random() < self.loss:
                    continue
                trimmed = data.rstrip(b"\0")  # MAVLink2 trims the payload's trailing zeros
                self.apply(self.capture.handle_block(CH, 1, LOG, ME, seqno, trimmed, self.now))
            self.apply(self.capture.tick(self.now))


class LogSource:
    """A real DataFlash log (the simulated flight recorder's) handed out in pieces."""

    def __init__(self, seconds: float = 60.0) -> None:
        state = VehicleState(lat=-35.36, lon=149.16, alt_amsl_m=584.0, home_lat=-35.36, home_lon=149.16,
                             home_alt_m=584.0)
        rec = FlightRecorder({0: "STABILIZE", 4: "GUIDED"})
        wall = 1.764e9
        parts = [rec.start(0.0, 0, wall, state, [(f"P{i}", float(i), 0.0) for i in range(200)], ["fake FC"])]
        t = 0.0
        while t < seconds:
            t += 0.01
            state.alt_amsl_m = 584.0 + t
            parts.append(rec.sample(t, int(t * 1e6), wall + t, state))
        self.data = b"".join(parts)
        self.pos = 0

    def take(self, n: int) -> bytes:
        out = self.data[self.pos:self.pos + n]
        self.pos += len(out)
        return out


def dfreader_types(tmp_path, data: bytes, name: str) -> dict[str, int]:
    path = tmp_path / name
    path.write_bytes(data)
    reader = DFReader.DFReader_binary(str(path))
    counts: dict[str, int] = {}
    while (m := reader.recv_match()) is not None:
        counts[m.get_type()] = counts.get(m.get_type(), 0) + 1
    return counts


def test_start_goes_to_the_autopilot_on_its_heartbeat_and_streaming_begins_at_seqno_0():
    h = Harness()
    assert h.sent[0] == Status(CH, 1, 1, SEQ_START, 1)
    assert h.fc.streaming and h.fc.client == ME
    h.fc.write(bytes(range(200)))
    h.run(0.02)
    assert h.order == [1] and bytes(h.files[1]) == bytes(range(200))
    assert Status(CH, 1, LOG, 0, ACK) in h.sent


def test_lost_blocks_are_nacked_and_the_file_is_byte_identical(tmp_path):
    h = Harness(loss=0.10, ack_loss=0.05)
    src = LogSource()
    h.run(8.0, produce_bytes_per_s=40_000, source=src)
    h.run(1.0)  # drain
    assert h.fc.dropped_bytes == 0
    assert any(s.status == NACK for s in h.sent)
    assert h.capture.stats.recovered > 0
    assert len(h.order) == 1
    assert bytes(h.files[1]) == h.fc.logged
    counts = dfreader_types(tmp_path, bytes(h.files[1]), "1.BIN")
    assert counts["GPS"] > 100 and counts["PARM"] == 200 and counts["FMT"] > 5


def test_a_pause_continues_the_same_file_and_never_sends_stop():
    h = Harness(loss=0.10)
    src = LogSource()
    h.run(2.0, produce_bytes_per_s=40_000, source=src)
    h.run(8.0)  # a pause: nothing logged for 8 s; the file is closed, STARTs are ignored
    assert h.closed == {1}
    h.run(2.0, produce_bytes_per_s=40_000, source=src)
    h.run(1.0)
    assert h.order == [1]
    assert bytes(h.files[1]) == h.fc.logged
    assert not any(s.seqno == STOP for s in h.sent)
    assert h.fc.starts == 1


def test_a_reboot_is_asked_to_start_again_and_gets_a_new_file(tmp_path):
    h = Harness(loss=0.10)
    src = LogSource()
    h.run(2.0, produce_bytes_per_s=40_000, source=src)
    h.run(0.5)
    first = h.fc.logged
    h.fc.reboot()
    h.run(1.5)  # silent: START again within START_INTERVAL_S
    assert h.fc.streaming and h.fc.starts == 2
    src2 = LogSource(30.0)
    h.run(2.0, produce_bytes_per_s=40_000, source=src2)
    h.run(1.0)
    assert h.order == [1, 2]
    assert bytes(h.files[1]) == first
    assert bytes(h.files[2]) == h.fc.logged
    assert dfreader_types(tmp_path, bytes(h.files[2]), "2.BIN")["GPS"] > 50


def test_a_flight_controller_that_timed_out_restarts_at_seqno_0_in_a_new_file():
    h = Harness()
    src = LogSource()
    h.run(1.0, produce_bytes_per_s=40_000, source=src)
    h.ack_loss = 1.0  # nothing reaches it for 12 s: it gives up (10 s)
    h.run(12.0, produce_bytes_per_s=40_000, source=src)
    assert not h.fc.streaming
    h.ack_loss = 0.0
    h.run(1.5)
    assert h.fc.streaming and h.fc.starts == 2
    h.run(1.0, produce_bytes_per_s=40_000, source=LogSource(10.0))
    h.run(0.5)
    assert h.order == [1, 2] and bytes(h.files[2]) == h.fc.logged


def test_an_orphan_stream_is_stopped_and_restarted_at_seqno_0():
    h = Harness()
    # the flight controller streams to us from our previous run: its seqnos start at 500
    effects = h.capture.handle_block(CH, 1, LOG, ME, 500, b"x" * 200, 0.5)
    assert [e.seqno for e in effects] == [STOP, START] and not h.files


def test_a_block_for_another_system_or_far_ahead_is_ignored():
    h = Harness()
    assert h.capture.handle_block(CH, 1, LOG, (7, 1), 0, b"a", 0.1) == []
    assert h.capture.handle_block(CH, 1, LOG, ME, 0, b"a", 0.1)  # a positive control: written
    assert h.capture.handle_block(CH, 1, LOG, ME, 5000, b"a", 0.1) == []
    assert h.capture.stats.ignored == 2


def test_a_duplicate_block_is_acked_again_and_not_counted_twice():
    c = Capture(*ME)
    c.handle_block(CH, 1, LOG, ME, 0, b"a", 0.0)
    again = c.handle_block(CH, 1, LOG, ME, 0, b"a", 0.05)
    assert again == [Status(CH, 1, LOG, 0, ACK)]
    assert c.stats.blocks == 1 and c.stats.duplicates == 1


def test_missing_blocks_are_nacked_every_100_ms_and_abandoned_after_60_s():
    c = Capture(*ME)
    c.handle_block(CH, 1, LOG, ME, 0, b"a", 0.0)
    c.handle_block(CH, 1, LOG, ME, 3, b"d", 0.0)
    first = [e for e in c.tick(0.0) if isinstance(e, Status) and e.status == NACK]
    assert [e.seqno for e in first] == [1, 2]
    assert [e for e in c.tick(0.05) if getattr(e, "status", None) == NACK] == []
    assert c.next_deadline(0.05) == pytest.approx(0.1)
    assert len([e for e in c.tick(0.1) if getattr(e, "status", None) == NACK]) == 2
    c.tick(60.0)
    assert c.stats.abandoned == 2 and c.next_deadline(60.0) is not None


def test_other_channels_are_not_captured_when_channels_are_named():
    c = Capture(*ME, channels=frozenset({1}))
    assert c.handle_heartbeat(0, 1, 1, 3, 0.0) == []
    assert c.handle_heartbeat(1, 1, 1, 3, 0.0) == [Status(1, 1, 1, SEQ_START, 1)]


def test_a_system_time_going_back_means_a_reboot_and_a_start():
    c = Capture(*ME)
    c.handle_heartbeat(CH, 1, 1, 3, 0.0)
    assert c.handle_system_time(1, 50_000, 0.5) == []
    assert c.handle_system_time(1, 200, 0.6) == [Status(CH, 1, 1, SEQ_START, 1)]


class StreamingSource(LogSource):
    """Log data produced only while the flight controller streams (its START may be lost too)."""

    def __init__(self, h: Harness, seconds: float = 60.0) -> None:
        super().__init__(seconds)
        self.h = h

    def take(self, n: int) -> bytes:
        return super().take(n) if self.h.fc.streaming else b""


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_third_of_everything_lost_both_ways_still_gives_byte_identical_logs(seed):
    h = Harness(loss=0.3, ack_loss=0.3, seed=seed)
    h.run(2.0)
    src = StreamingSource(h)
    h.run(3.0, produce_bytes_per_s=20_000, source=src)
    h.run(6.0)  # a pause
    h.run(2.0, produce_bytes_per_s=20_000, source=src)
    h.run(3.0)
    first = h.fc.logged
    h.fc.reboot()
    h.run(3.0)
    h.run(3.0, produce_bytes_per_s=20_000, source=StreamingSource(h, 30.0))
    h.run(4.0)
    assert h.fc.dropped_bytes == 0 and len(first) > 40_000 and len(h.fc.logged) > 20_000
    assert [bytes(h.files[k]) for k in h.order] == [first, h.fc.logged]
