"""ParamService with a float clock and no I/O: reads, sets, the paced list, and the write-behind
deadlines (when mav.parm is due, what is written, what a failure does)."""

from __future__ import annotations

import math
import struct
from pathlib import Path
from types import SimpleNamespace

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

import gcsd.vehicle.services.params as params_module
from gcsd.vehicle.params import INT16, REAL32, ParamDef, ParamStore
from gcsd.vehicle.params.parmfile import parse_parm
from gcsd.vehicle.services import Incoming
from gcsd.vehicle.services.params import (
    BURST,
    BURST_INTERVAL_S,
    PARAM_VALUE_BYTES,
    PERSIST_INTERVAL_S,
    ParamService,
)

GCS = (255, 190)


class FakeChannel:
    def __init__(self, index: int, room_bytes: float = math.inf, private: bool = False,
                 kind: str = "udp-server") -> None:
        self.index = index
        self.config = SimpleNamespace(type=kind)  # a datagram link: the list is paced there
        self.peers = {"peer": object()}
        self.policy = SimpleNamespace(private=private)
        self.room_bytes = room_bytes
        self.sent: list = []

    def has_room(self, nbytes: int) -> bool:
        return self.room_bytes >= nbytes

    def budget_wait_s(self, nbytes: int) -> float:
        return 0.25


class FakeContext:
    """What ParamService asks of its ServiceContext, recorded."""

    def __init__(self, channels: list[FakeChannel]) -> None:
        self.channels = channels
        self.texts: list[tuple[int, str, set | None]] = []
        self.slow: list[tuple[int, bool]] = []
        self.woken: list[int] = []

    def reply(self, channel, msg) -> bool:
        channel.sent.append(msg)
        return True

    def text(self, severity, text, channels=None) -> None:
        self.texts.append((severity, text, channels))

    def banner(self) -> None:
        self.texts.append((M.MAV_SEVERITY_INFO, "banner", None))

    def link(self, channel):
        return SimpleNamespace(set_slow=lambda name, on: self.slow.append((channel.index, on)))

    def wake(self, channel) -> None:
        self.woken.append(channel.index)


def defs() -> list[ParamDef]:
    return [
        ParamDef("ANGLE_MAX", INT16, 3000, 1000, 8000),
        ParamDef("COMPASS_OFS_X", REAL32, 0.0, -400, 400),
        ParamDef("FORMAT_VERSION", INT16, 120, read_only=True),
        ParamDef("STAT_RUNTIME", REAL32, 0, read_only=True),
        *(ParamDef(f"P{i:04d}", INT16, 0) for i in range(250)),
    ]


@pytest.fixture
def svc(tmp_path):
    channels = [FakeChannel(0), FakeChannel(1), FakeChannel(2, private=True)]
    service = ParamService(FakeContext(channels), ParamStore(defs()), tmp_path / "mav.parm", now=100.0)
    service.dirty_calls = []
    service.on_dirty = lambda: service.dirty_calls.append(True)
    return service


def incoming(msg, channel, now: float) -> Incoming:
    frame = SimpleNamespace(sysid=GCS[0], compid=GCS[1])
    return Incoming(msg, frame, channel, now)


def param_set(svc, name: str, value: float, now: float, channel_index: int = 0) -> None:
    msg = M.MAVLink_param_set_message(1, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32)
    svc.handle_PARAM_SET(incoming(msg, svc.ctx.channels[channel_index], now))


def values_of(channel) -> list[tuple[str, float]]:
    return [(m.param_id, m.param_value) for m in channel.sent if m.get_type() == "PARAM_VALUE"]


# --- reads and sets ------------------------------------------------------------------------------


def test_set_is_confirmed_on_every_non_private_channel_with_the_real_index(svc):
    param_set(svc, "ANGLE_MAX", 4500, now=100.0)
    ch0, ch1, private = svc.ctx.channels
    assert values_of(ch0) == values_of(ch1) == [("ANGLE_MAX", 4500.0)]
    assert [m.param_index for m in ch0.sent] == [svc.store.index_of("ANGLE_MAX")]
    assert private.sent == []


def test_read_by_name_and_by_index_answer_on_the_requesting_channel_only(svc):
    ch0, ch1, _ = svc.ctx.channels
    index = svc.store.index_of("COMPASS_OFS_X")
    svc.handle_PARAM_REQUEST_READ(incoming(M.MAVLink_param_request_read_message(1, 1, b"COMPASS_OFS_X", -1), ch1, 1.0))
    svc.handle_PARAM_REQUEST_READ(incoming(M.MAVLink_param_request_read_message(1, 1, b"", index), ch1, 1.0))
    assert [(m.param_id, m.param_index) for m in ch1.sent] == [("COMPASS_OFS_X", index)] * 2
    assert ch0.sent == []


def test_unknown_name_or_index_gets_no_reply_while_a_known_one_does(svc):
    ch0 = svc.ctx.channels[0]
    for msg in (M.MAVLink_param_request_read_message(1, 1, b"NO_SUCH", -1),
                M.MAVLink_param_request_read_message(1, 1, b"", 60000),
                M.MAVLink_param_request_read_message(1, 1, b"ANGLE_MAX", -1)):
        svc.handle_PARAM_REQUEST_READ(incoming(msg, ch0, 1.0))
    assert values_of(ch0) == [("ANGLE_MAX", 3000.0)]


def test_read_only_write_is_refused_with_text_and_the_old_value_and_nothing_to_persist(svc):
    param_set(svc, "FORMAT_VERSION", 7, now=100.0)
    ch0, ch1, _ = svc.ctx.channels
    assert values_of(ch0) == [("FORMAT_VERSION", 120.0)] and ch1.sent == []
    assert svc.ctx.texts == [(M.MAV_SEVERITY_WARNING, "Param write denied (FORMAT_VERSION)", {0})]
    assert svc.persist_deadline() is None and svc.dirty_calls == []


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_nan_and_infinity_change_nothing_and_persist_nothing(svc, value):
    param_set(svc, "COMPASS_OFS_X", value, now=100.0)
    assert svc.store.get("COMPASS_OFS_X") == 0.0
    assert svc.ctx.channels[0].sent == [] and svc.persist_deadline() is None


# --- write-behind deadlines ----------------------------------------------------------------------


def test_a_first_change_is_due_at_once_and_the_text_holds_it(svc):
    param_set(svc, "ANGLE_MAX", 4500, now=100.0)
    assert svc.dirty_calls == [True]
    assert svc.persist_deadline() <= 100.0
    text = svc.take_persist(100.0)
    values, problems = parse_parm(text)
    assert problems == [] and values["ANGLE_MAX"] == 4500
    assert svc.persist_deadline() is None and svc.take_persist(100.5) is None


def test_changes_within_a_second_of_a_write_are_due_one_interval_after_it(svc):
    param_set(svc, "ANGLE_MAX", 4500, now=100.0)
    assert svc.take_persist(100.0) is not None
    param_set(svc, "ANGLE_MAX", 4600, now=100.2)
    param_set(svc, "ANGLE_MAX", 4700, now=100.7)
    assert svc.persist_deadline() == 100.0 + PERSIST_INTERVAL_S
    assert svc.take_persist(100.99) is None
    values, _ = parse_parm(svc.take_persist(101.0))
    assert values["ANGLE_MAX"] == 4700  # the latest value, once


def test_one_thousand_sets_in_one_second_are_two_writes(svc):
    writes = []
    now = 100.0
    for i in range(1000):
        now = 100.0 + i / 1000
        param_set(svc, f"P{i % 250:04d}", i + 1, now=now)  # every one a change
        deadline = svc.persist_deadline()
        if deadline is not None and deadline <= now:  # what the writer's timer does at its deadline
            writes.append((now, svc.take_persist(now)))
    assert len(writes) == 1 and svc.persist_deadline() == 101.0
    writes.append((101.0, svc.take_persist(101.0)))
    values, _ = parse_parm(writes[-1][1])
    assert [values[f"P{i:04d}"] for i in range(5)] == [751, 752, 753, 754, 755]  # the last round
    assert len(writes) == 2


def test_a_quiet_second_after_a_write_makes_the_next_change_due_at_once(svc):
    param_set(svc, "ANGLE_MAX", 4500, now=100.0)
    svc.take_persist(100.0)
    param_set(svc, "ANGLE_MAX", 4600, now=105.0)
    assert svc.persist_deadline() <= 105.0


def test_stat_runtime_counts_from_the_start_time_given_by_the_caller(svc):
    param_set(svc, "ANGLE_MAX", 4500, now=160.0)
    values, _ = parse_parm(svc.take_persist(160.0))
    assert values["STAT_RUNTIME"] == 60  # started at now=100.0


def test_force_takes_the_text_before_the_deadline_for_a_clean_stop(svc):
    param_set(svc, "ANGLE_MAX", 4500, now=100.0)
    svc.take_persist(100.0)
    param_set(svc, "ANGLE_MAX", 4600, now=100.1)
    assert svc.take_persist(100.1) is None
    assert parse_parm(svc.take_persist(100.1, force=True))[0]["ANGLE_MAX"] == 4600


def test_a_failed_write_is_retried_an_interval_later_and_reported_once(svc):
    param_set(svc, "ANGLE_MAX", 4500, now=100.0)
    svc.take_persist(100.0)
    svc.persist_failed("No space left on device")
    assert svc.persist_deadline() == 101.0
    svc.take_persist(101.0)
    svc.persist_failed("No space left on device")
    errors = [t for t in svc.ctx.texts if t[0] == M.MAV_SEVERITY_ERROR]
    assert errors == [(M.MAV_SEVERITY_ERROR, "Param save failed", None)]
    svc.take_persist(102.0)
    svc.persist_done()
    svc.persist_failed("again")
    assert len([t for t in svc.ctx.texts if t[0] == M.MAV_SEVERITY_ERROR]) == 2


def test_real32_values_are_written_to_read_back_bit_exact(svc):
    param_set(svc, "COMPASS_OFS_X", 0.35000002, now=100.0)
    values, _ = parse_parm(svc.take_persist(100.0))
    assert struct.pack("<f", values["COMPASS_OFS_X"]) == struct.pack("<f", svc.store.get("COMPASS_OFS_X"))


def test_without_a_save_path_nothing_is_ever_due(tmp_path):
    svc = ParamService(FakeContext([FakeChannel(0)]), ParamStore(defs()), None, now=0.0)
    param_set(svc, "ANGLE_MAX", 4500, now=1.0)
    assert svc.persist_deadline() is None


def test_the_service_reads_no_clock():
    assert not hasattr(params_module, "time")
    source = Path(params_module.__file__).read_text()
    assert "monotonic" not in source and "time.time" not in source


# --- the paced list ----------------------------------------------------------------------------------


def request_list(svc, channel, now: float = 1.0) -> None:
    svc.handle_PARAM_REQUEST_LIST(incoming(M.MAVLink_param_request_list_message(1, 1), channel, now))


def test_list_sends_the_banner_slows_telemetry_and_streams_burst_per_pass(svc):
    ch0 = svc.ctx.channels[0]
    request_list(svc, ch0)
    assert svc.ctx.texts[0][1] == "banner" and svc.ctx.slow == [(0, True)] and svc.ctx.woken == [0]
    sent = []
    now = 1.0
    deadline = svc.pending(ch0, now, lambda m: sent.append(m) or True)
    assert deadline == now + BURST_INTERVAL_S  # a full burst: the next one after the interval
    assert len(sent) == BURST and [m.param_index for m in sent] == list(range(BURST))
    while deadline is not None:
        now = deadline
        deadline = svc.pending(ch0, now, lambda m: sent.append(m) or True)
    assert [m.param_index for m in sent] == list(range(len(svc.store)))
    assert now == 1.0 + (len(svc.store) // BURST) * BURST_INTERVAL_S
    assert svc.ctx.slow == [(0, True), (0, False)]


def test_a_stream_link_has_flow_control_so_its_list_is_not_paced(svc):
    ch0 = svc.ctx.channels[0]
    ch0.config = SimpleNamespace(type="tcp-server")
    request_list(svc, ch0)
    sent = []
    assert svc.pending(ch0, 1.0, lambda m: sent.append(m) or True) == 1.0  # at once again
    assert len(sent) == BURST


def test_list_on_a_spent_budget_comes_back_when_the_budget_allows(svc):
    ch0 = svc.ctx.channels[0]
    ch0.room_bytes = 3 * PARAM_VALUE_BYTES
    request_list(svc, ch0)
    sent = []

    def send(m) -> bool:
        ch0.room_bytes -= PARAM_VALUE_BYTES
        sent.append(m)
        return True

    assert svc.pending(ch0, 5.0, send) == 5.0 + 0.25
    assert len(sent) == 3
    ch0.room_bytes = 10 * PARAM_VALUE_BYTES
    svc.pending(ch0, 5.25, send)
    assert [m.param_index for m in sent] == list(range(13))


def test_two_requesters_on_one_channel_each_get_every_index(svc):
    ch0 = svc.ctx.channels[0]
    request_list(svc, ch0)
    frame = SimpleNamespace(sysid=254, compid=190)
    svc.handle_PARAM_REQUEST_LIST(Incoming(M.MAVLink_param_request_list_message(1, 1), frame, ch0, 1.0))
    sent = []
    while svc.pending(ch0, 1.0, lambda m: sent.append(m) or True) is not None:
        pass
    assert sorted(m.param_index for m in sent) == sorted(list(range(len(svc.store))) * 2)
