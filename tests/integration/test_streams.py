"""Measured telemetry rates and the message-rate commands (REFERENCE.md sections 4 and 5).

Rates are measured from arrival times on a real UDP socket: (n - 1) intervals between the first
and the last copy, which must be within 10 % of what was asked (SPEC.md: up to 50 Hz).
"""

from __future__ import annotations

import pytest

from .helpers import (
    VEHICLE,
    Client,
    M,
    Received,
    from_vehicle,
    is_ack,
    measure_rates,
    pump,
    pump_until,
    udp_channel,
    udp_url,
    wait_for,
)

TOLERANCE = 0.10
ATTITUDE = M.MAVLINK_MSG_ID_ATTITUDE
STREAMS = {"extra1": 4, "position": 2}  # ATTITUDE at 4 Hz, GLOBAL_POSITION_INT at 2 Hz
SET_INTERVAL = M.MAV_CMD_SET_MESSAGE_INTERVAL
GET_INTERVAL = M.MAV_CMD_GET_MESSAGE_INTERVAL
REQUEST_MESSAGE = M.MAV_CMD_REQUEST_MESSAGE


def within(measured: float, expected: float) -> bool:
    return abs(measured - expected) <= TOLERANCE * expected


def _gcs(daemon, client, *extra_channels: dict, streams=STREAMS, **options) -> tuple[object, Client]:
    d = daemon({"channels": [udp_channel("gcs", streams=dict(streams), **options), *extra_channels]})
    c = client(udp_url(d.port("gcs")), 255, 190)
    c.heartbeat()
    assert wait_for(c, from_vehicle), "nothing from the vehicle"
    return d, c


@pytest.fixture
def gcs(daemon, client) -> Client:
    return _gcs(daemon, client)[1]


def command(c: Client, cmd: int, *params: float, use_int: bool = False, timeout: float = 2.0) -> Received:
    """Send a command to the vehicle and return its COMMAND_ACK."""
    mark = c.mark()
    if use_int:
        p = list(params) + [0.0] * (4 - len(params))
        c.command_int(cmd, *p[:4])
    else:
        c.command_long(cmd, *params)
    ack = wait_for(c, is_ack(cmd), timeout=timeout, since=mark)
    assert ack is not None, f"no COMMAND_ACK for command {cmd}"
    return ack


def _types(c: Client, mark: int) -> set[str]:
    return {r.type for r in c.since(mark) if r.src == VEHICLE}


def _heard(c: Client, mark: int, kinds: set[str]) -> bool:
    return kinds <= _types(c, mark)


def attitude_rate(c: Client, seconds: float) -> float:
    return measure_rates({"c": c}, {"c": ("ATTITUDE",)}, seconds)[("c", "ATTITUDE")]


def count(c: Client, kind: str, seconds: float) -> int:
    mark = c.mark()
    pump([c], seconds)
    return len([r for r in c.since(mark, kind) if r.src == VEHICLE])


# --- stream rates from configuration --------------------------------------------------------

def test_configured_stream_rates_and_heartbeat_are_measured_within_ten_percent(gcs):
    rates = measure_rates({"c": gcs}, {"c": ("ATTITUDE", "GLOBAL_POSITION_INT", "HEARTBEAT")}, 3.2)
    assert within(rates[("c", "ATTITUDE")], STREAMS["extra1"]), rates
    assert within(rates[("c", "GLOBAL_POSITION_INT")], STREAMS["position"]), rates
    assert within(rates[("c", "HEARTBEAT")], 1.0), rates


# --- SET_MESSAGE_INTERVAL --------------------------------------------------------------------

@pytest.mark.parametrize(
    ("rate_hz", "seconds"), [(1, 4.6), (5, 2.2), (10, 1.6), (20, 1.2), (50, 1.0)], ids=lambda v: str(v)
)
def test_set_message_interval_rate_is_measured_within_ten_percent(gcs, rate_hz, seconds):
    ack = command(gcs, SET_INTERVAL, ATTITUDE, 1e6 / rate_hz)
    assert ack.msg.result == M.MAV_RESULT_ACCEPTED  # whatever was sent before came before the ACK
    measured = attitude_rate(gcs, seconds)
    assert within(measured, rate_hz), f"asked {rate_hz} Hz, measured {measured:.2f} Hz"


def test_set_message_interval_by_command_int(gcs):
    ack = command(gcs, SET_INTERVAL, ATTITUDE, 1e6 / 20, use_int=True)
    assert ack.msg.result == M.MAV_RESULT_ACCEPTED
    measured = attitude_rate(gcs, 1.2)
    assert within(measured, 20), measured


def test_interval_zero_restores_the_stream_rate(gcs):
    assert command(gcs, SET_INTERVAL, ATTITUDE, 1e6 / 20).msg.result == M.MAV_RESULT_ACCEPTED
    assert command(gcs, SET_INTERVAL, ATTITUDE, 0).msg.result == M.MAV_RESULT_ACCEPTED
    measured = attitude_rate(gcs, 2.6)
    assert within(measured, STREAMS["extra1"]), measured


def test_interval_minus_one_stops_the_message(gcs):
    assert command(gcs, SET_INTERVAL, ATTITUDE, -1).msg.result == M.MAV_RESULT_ACCEPTED
    mark = gcs.mark()
    # the same stream (extra1) and the rest carry on: the controls are awaited after the 1.2 s
    # window (a 1 Hz HEARTBEAT late under load is no reason to fail), ATTITUDE is absent from all of it
    assert pump_until([gcs], lambda: _heard(gcs, mark, {"AHRS2", "HEARTBEAT"}), at_least_s=1.2), \
        f"the other messages stopped too: {_types(gcs, mark)}"
    assert "ATTITUDE" not in _types(gcs, mark)
    mark = gcs.mark()
    ack = command(gcs, GET_INTERVAL, ATTITUDE)
    assert ack.msg.result == M.MAV_RESULT_ACCEPTED
    (reply,) = gcs.since(mark, "MESSAGE_INTERVAL")
    assert (reply.msg.message_id, reply.msg.interval_us) == (ATTITUDE, -1)


@pytest.mark.parametrize(
    ("why", "params"),
    [
        ("negative interval other than -1", (ATTITUDE, -5)),
        ("param3 (response target) not 0", (ATTITUDE, 100_000, 1)),
        ("message id without a mapping", (145, 100_000)),
        ("message id unknown to MAVLink", (9999, 100_000)),
    ],
    ids=["minus_five", "param3", "unmapped_145", "unknown_9999"],
)
def test_set_message_interval_is_denied(gcs, why, params):
    ack = command(gcs, SET_INTERVAL, *params)
    assert ack.msg.result == M.MAV_RESULT_DENIED, why


def test_interval_faster_than_the_loop_cap_is_denied_with_a_statustext(gcs):
    mark = gcs.mark()
    ack = command(gcs, SET_INTERVAL, ATTITUDE, 1000)  # 1 kHz
    assert ack.msg.result == M.MAV_RESULT_DENIED
    text = wait_for(gcs, lambda r: r.type == "STATUSTEXT" and "too fast" in r.msg.text, since=mark)
    assert text is not None and text.src == VEHICLE
    assert str(ATTITUDE) in text.msg.text
    assert within(attitude_rate(gcs, 1.6), STREAMS["extra1"])  # the old rate stays


# --- GET_MESSAGE_INTERVAL and REQUEST_MESSAGE -------------------------------------------------

def test_get_message_interval_answers_before_the_ack(gcs):
    mark = gcs.mark()
    ack = command(gcs, GET_INTERVAL, ATTITUDE)
    assert ack.msg.result == M.MAV_RESULT_ACCEPTED
    replies = [r for r in gcs.since(mark) if r.type in ("MESSAGE_INTERVAL", "COMMAND_ACK")]
    assert [r.type for r in replies] == ["MESSAGE_INTERVAL", "COMMAND_ACK"]
    assert (replies[0].msg.message_id, replies[0].msg.interval_us) == (ATTITUDE, int(1e6 / STREAMS["extra1"]))
    assert replies[0].src == VEHICLE


def test_get_message_interval_reports_a_set_interval(gcs):
    assert command(gcs, SET_INTERVAL, ATTITUDE, 1e6 / 20).msg.result == M.MAV_RESULT_ACCEPTED
    mark = gcs.mark()
    command(gcs, GET_INTERVAL, ATTITUDE)
    (reply,) = gcs.since(mark, "MESSAGE_INTERVAL")
    assert reply.msg.interval_us == 50_000


def test_get_message_interval_of_an_unmapped_id_fails_with_interval_zero(gcs):
    mark = gcs.mark()
    ack = command(gcs, GET_INTERVAL, 9999)
    assert ack.msg.result == M.MAV_RESULT_FAILED
    replies = [r for r in gcs.since(mark) if r.type in ("MESSAGE_INTERVAL", "COMMAND_ACK")]
    assert [r.type for r in replies] == ["MESSAGE_INTERVAL", "COMMAND_ACK"]
    assert (replies[0].msg.message_id, replies[0].msg.interval_us) == (9999, 0)


def test_request_message_of_message_interval_is_get_message_interval(gcs):
    mark = gcs.mark()
    position = M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT
    ack = command(gcs, REQUEST_MESSAGE, M.MAVLINK_MSG_ID_MESSAGE_INTERVAL, position)
    assert ack.msg.result == M.MAV_RESULT_ACCEPTED
    replies = [r for r in gcs.since(mark) if r.type in ("MESSAGE_INTERVAL", "COMMAND_ACK")]
    assert [r.type for r in replies] == ["MESSAGE_INTERVAL", "COMMAND_ACK"]
    reply = replies[0].msg
    assert (reply.message_id, reply.interval_us) == (position, int(1e6 / STREAMS["position"]))


def test_request_message_sends_exactly_one_copy(gcs):
    mark = gcs.mark()
    ack = command(gcs, REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert ack.msg.result == M.MAV_RESULT_ACCEPTED
    pump([gcs], 2.0)
    copies = [r for r in gcs.since(mark, "AUTOPILOT_VERSION") if r.src == VEHICLE]
    assert len(copies) == 1


def test_request_message_of_an_unmapped_id_fails(gcs):
    assert command(gcs, REQUEST_MESSAGE, 9999).msg.result == M.MAV_RESULT_FAILED


# --- REQUEST_DATA_STREAM ----------------------------------------------------------------------

def _request_data_stream(c: Client, stream_id: int, rate_hz: int, start: int = 1) -> None:
    c.send(M.MAVLink_request_data_stream_message(*VEHICLE, stream_id, rate_hz, start))


def barrier(c: Client) -> None:
    """REQUEST_DATA_STREAM has no reply: a command's ACK shows everything before it was handled."""
    command(c, GET_INTERVAL, ATTITUDE)


def test_request_data_stream_sets_a_stream_rate(gcs):
    _request_data_stream(gcs, M.MAV_DATA_STREAM_EXTRA1, 10)
    barrier(gcs)
    measured = attitude_rate(gcs, 1.6)
    assert within(measured, 10), measured
    mark = gcs.mark()
    command(gcs, GET_INTERVAL, ATTITUDE)
    assert gcs.since(mark, "MESSAGE_INTERVAL")[0].msg.interval_us == 100_000


def test_request_data_stream_overrides_an_earlier_message_interval(gcs):
    assert command(gcs, SET_INTERVAL, ATTITUDE, 1e6 / 20).msg.result == M.MAV_RESULT_ACCEPTED
    _request_data_stream(gcs, M.MAV_DATA_STREAM_EXTRA1, 5)
    barrier(gcs)
    assert within(attitude_rate(gcs, 1.8), 5)


def test_request_data_stream_start_stop_zero_stops_the_stream(gcs):
    _request_data_stream(gcs, M.MAV_DATA_STREAM_EXTRA1, 10, start=0)
    _request_data_stream(gcs, M.MAV_DATA_STREAM_POSITION, 10, start=0)
    barrier(gcs)
    mark = gcs.mark()
    # other streams carry on (awaited past the 1.2 s window, as above); the stopped ones are absent
    assert pump_until([gcs], lambda: _heard(gcs, mark, {"HEARTBEAT", "VFR_HUD"}), at_least_s=1.2), \
        f"the other streams stopped too: {_types(gcs, mark)}"
    assert not _types(gcs, mark) & {"ATTITUDE", "AHRS2", "SIMSTATE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"}


# --- no_stream_override ----------------------------------------------------------------------

def test_no_stream_override_ignores_request_data_stream_and_denies_intervals(daemon, client):
    _, c = _gcs(daemon, client, options=["no_stream_override"])
    _request_data_stream(c, M.MAV_DATA_STREAM_EXTRA1, 20)
    _request_data_stream(c, M.MAV_DATA_STREAM_POSITION, 0, start=0)
    assert command(c, SET_INTERVAL, ATTITUDE, 1e6 / 20).msg.result == M.MAV_RESULT_DENIED
    rates = measure_rates({"c": c}, {"c": ("ATTITUDE", "GLOBAL_POSITION_INT")}, 2.1)
    assert within(rates[("c", "ATTITUDE")], STREAMS["extra1"]), rates
    assert within(rates[("c", "GLOBAL_POSITION_INT")], STREAMS["position"]), rates


# --- per channel -----------------------------------------------------------------------------

def test_rates_are_per_channel(daemon, client):
    d, gcs1 = _gcs(daemon, client, udp_channel("gcs2", streams=dict(STREAMS)))
    gcs2 = client(udp_url(d.port("gcs2")), 254, 190)
    gcs2.heartbeat()
    assert wait_for(gcs2, from_vehicle)
    _request_data_stream(gcs1, M.MAV_DATA_STREAM_POSITION, 10)
    assert command(gcs1, SET_INTERVAL, ATTITUDE, 1e6 / 20).msg.result == M.MAV_RESULT_ACCEPTED
    kinds = ("ATTITUDE", "GLOBAL_POSITION_INT")
    rates = measure_rates({"gcs1": gcs1, "gcs2": gcs2}, {"gcs1": kinds, "gcs2": kinds}, 2.1)
    assert within(rates[("gcs1", "ATTITUDE")], 20), rates
    assert within(rates[("gcs1", "GLOBAL_POSITION_INT")], 10), rates
    assert within(rates[("gcs2", "ATTITUDE")], STREAMS["extra1"]), rates
    assert within(rates[("gcs2", "GLOBAL_POSITION_INT")], STREAMS["position"]), rates
    mark = gcs2.mark()
    command(gcs2, GET_INTERVAL, ATTITUDE)
    assert gcs2.since(mark, "MESSAGE_INTERVAL")[0].msg.interval_us == 250_000


# --- COMMAND_ACK -----------------------------------------------------------------------------

def test_every_command_gets_exactly_one_ack(gcs):
    commands = [
        (GET_INTERVAL, ATTITUDE),
        (SET_INTERVAL, ATTITUDE, 1e6 / 4),
        (SET_INTERVAL, ATTITUDE, -5),
        (REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION),
        (M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 1),
        (31999,),
        (M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 5),
    ]
    mark = gcs.mark()
    for cmd in commands:
        gcs.command_long(*cmd)

    def acks() -> list[int]:
        return sorted(r.msg.command for r in gcs.since(mark, "COMMAND_ACK") if r.src == VEHICLE)

    # a second copy would come within the 1 s window; every ACK is awaited, however late
    pump_until([gcs], lambda: len(acks()) >= len(commands), at_least_s=1.0)
    assert acks() == sorted(c[0] for c in commands)


def test_unknown_command_is_unsupported(gcs):
    ack = command(gcs, 31999)
    assert ack.msg.result == M.MAV_RESULT_UNSUPPORTED
    assert (ack.msg.target_system, ack.msg.target_component) == (255, 190)


def test_unknown_command_int_is_unsupported(gcs):
    assert command(gcs, 31999, use_int=True).msg.result == M.MAV_RESULT_UNSUPPORTED
