"""RatesService with a float clock: REQUEST_DATA_STREAM, SET/GET_MESSAGE_INTERVAL and REQUEST_MESSAGE
as REFERENCE.md section 5 states them, through the real VehicleNode (tests/unit/vehicle_harness.py).

No sockets and no event loop: messages go in through the node's dispatch, time is a float the
test advances, and rates are counted over a fake-time window, so they are exact, not within
a tolerance. The copter's default rates (SPEC.md) are ATTITUDE 5 Hz (extra1), GLOBAL_POSITION_INT
2 Hz (position), VFR_HUD 5 Hz (extra2), HEARTBEAT 1 Hz.
"""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M
from vehicle_harness import Harness

ATTITUDE, AHRS2, SIMSTATE = M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_AHRS2, M.MAVLINK_MSG_ID_SIMSTATE
GLOBAL_POSITION_INT, VFR_HUD = M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_VFR_HUD
SET, GET = M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAV_CMD_GET_MESSAGE_INTERVAL
ACCEPTED, DENIED, FAILED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_DENIED, M.MAV_RESULT_FAILED
WINDOW_S = 4.0
STEP_S = 0.01


@pytest.fixture
def h(tmp_path) -> Harness:
    h = Harness(tmp_path)
    h.run(1.0, step=STEP_S)  # past start-up: every stream at its configured rate
    return h


def rates(h: Harness, seconds: float = WINDOW_S) -> dict[str, float]:
    """Messages per second of each type the node sent over `seconds` of fake time, counted after
    1 s of settling (a changed interval starts from the message's last send)."""
    h.run(1.0, step=STEP_S)
    mark = h.mark()
    h.run(seconds, step=STEP_S)
    counts: dict[str, int] = {}
    for m in h.received[mark:]:
        counts[m.get_type()] = counts.get(m.get_type(), 0) + 1
    return {name: n / seconds for name, n in counts.items()}


def request_data_stream(h: Harness, stream: int, rate_hz: int, start_stop: int = 1) -> list:
    mark = h.mark()
    h.send(M.MAVLink_request_data_stream_message(*h_target(h), stream, rate_hz, start_stop))
    return h.received[mark:]


def h_target(h: Harness) -> tuple[int, int]:
    return h.node.sysid, h.node.compid


def interval_us(h: Harness, msgid: int, command: int = GET) -> tuple[int | None, tuple[int, int] | None]:
    """The ACK result and the MESSAGE_INTERVAL (message_id, interval_us) a query gets."""
    mark = h.mark()
    if command == GET:
        result = h.command(GET, msgid)
    else:
        result = h.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_MESSAGE_INTERVAL, msgid)
    replies = h.of_type("MESSAGE_INTERVAL", mark)
    assert len(replies) <= 1
    return result, ((replies[0].message_id, replies[0].interval_us) if replies else None)


def no_override_harness(tmp_path) -> Harness:
    h = Harness(tmp_path, config={"channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0",
                                                "options": ["no_stream_override"]}]})
    h.run(1.0, step=STEP_S)
    return h


# --- REQUEST_DATA_STREAM --------------------------------------------------------------------

def test_request_data_stream_sets_every_message_of_the_stream_and_nothing_else(h):
    assert request_data_stream(h, M.MAV_DATA_STREAM_EXTRA1, 10) == [], "REQUEST_DATA_STREAM has no reply"
    got = rates(h)
    assert (got["ATTITUDE"], got["AHRS2"], got["SIMSTATE"]) == (10.0, 10.0, 10.0)
    assert (got["VFR_HUD"], got["GLOBAL_POSITION_INT"], got["HEARTBEAT"]) == (5.0, 2.0, 1.0)


def test_request_data_stream_start_stop_zero_stops_the_stream_whatever_the_rate(h):
    request_data_stream(h, M.MAV_DATA_STREAM_POSITION, 10, start_stop=0)
    got = rates(h)
    assert "GLOBAL_POSITION_INT" not in got and "LOCAL_POSITION_NED" not in got
    assert (got["ATTITUDE"], got["HEARTBEAT"]) == (5.0, 1.0)  # the others carry on
    assert interval_us(h, GLOBAL_POSITION_INT) == (ACCEPTED, (GLOBAL_POSITION_INT, -1))


@pytest.mark.parametrize("start_stop", [2, 255])
def test_request_data_stream_with_another_start_stop_value_is_ignored(h, start_stop):
    request_data_stream(h, M.MAV_DATA_STREAM_EXTRA1, 10, start_stop=start_stop)
    assert rates(h)["ATTITUDE"] == 5.0


def test_request_data_stream_all_sets_every_stream(h):
    request_data_stream(h, M.MAV_DATA_STREAM_ALL, 4)
    got = rates(h)
    for name in ("RAW_IMU", "SYS_STATUS", "RC_CHANNELS", "GLOBAL_POSITION_INT", "ATTITUDE", "VFR_HUD", "AHRS"):
        assert got[name] == 4.0, name
    assert got["HEARTBEAT"] == 1.0  # not in any stream


@pytest.mark.parametrize("stream", [M.MAV_DATA_STREAM_ENUM_END, 5, 7, 9, 13, 200])
def test_request_data_stream_for_an_unknown_stream_id_changes_nothing(h, stream):
    request_data_stream(h, stream, 10)
    got = rates(h)
    assert (got["ATTITUDE"], got["GLOBAL_POSITION_INT"], got["RAW_IMU"]) == (5.0, 2.0, 2.0)


def test_request_data_stream_overrides_an_earlier_message_interval(h):
    assert h.command(SET, ATTITUDE, 50_000) == ACCEPTED  # 20 Hz
    assert rates(h, 2.0)["ATTITUDE"] == 20.0
    request_data_stream(h, M.MAV_DATA_STREAM_EXTRA1, 2)
    assert rates(h)["ATTITUDE"] == 2.0
    assert interval_us(h, ATTITUDE) == (ACCEPTED, (ATTITUDE, 500_000))


def test_request_data_stream_is_ignored_on_a_no_stream_override_channel(tmp_path):
    h = no_override_harness(tmp_path)
    request_data_stream(h, M.MAV_DATA_STREAM_EXTRA1, 10)
    request_data_stream(h, M.MAV_DATA_STREAM_POSITION, 0, start_stop=0)
    got = rates(h)
    assert (got["ATTITUDE"], got["GLOBAL_POSITION_INT"]) == (5.0, 2.0)


# --- SET_MESSAGE_INTERVAL -------------------------------------------------------------------

def test_set_message_interval_sets_the_rate_of_that_message_only(h):
    assert h.command(SET, ATTITUDE, 50_000) == ACCEPTED
    got = rates(h)
    assert got["ATTITUDE"] == 20.0
    assert (got["AHRS2"], got["SIMSTATE"]) == (5.0, 5.0), "the rest of extra1 keeps its rate"
    assert interval_us(h, ATTITUDE) == (ACCEPTED, (ATTITUDE, 50_000))


def test_set_message_interval_minus_one_stops_the_message(h):
    assert h.command(SET, ATTITUDE, -1) == ACCEPTED
    got = rates(h)
    assert "ATTITUDE" not in got
    assert got["AHRS2"] == 5.0
    assert interval_us(h, ATTITUDE) == (ACCEPTED, (ATTITUDE, -1))


def test_set_message_interval_zero_restores_the_stream_rate(h):
    assert h.command(SET, ATTITUDE, 50_000) == ACCEPTED
    assert h.command(SET, ATTITUDE, 0) == ACCEPTED
    assert rates(h)["ATTITUDE"] == 5.0
    assert interval_us(h, ATTITUDE) == (ACCEPTED, (ATTITUDE, 200_000))


def test_set_message_interval_can_stream_a_message_that_has_no_stream_rate(h):
    assert interval_us(h, M.MAVLINK_MSG_ID_HOME_POSITION)[1] == (M.MAVLINK_MSG_ID_HOME_POSITION, -1)
    assert h.command(SET, M.MAVLINK_MSG_ID_HOME_POSITION, 500_000) == ACCEPTED
    assert rates(h)["HOME_POSITION"] == 2.0


@pytest.mark.parametrize(
    ("interval", "param3", "why"),
    [(50_000, 1, "param3 (response target) must be 0"), (-2, 0, "negative other than -1"),
     (-1000, 0, "negative other than -1")],
)
def test_set_message_interval_is_denied_and_changes_nothing(h, interval, param3, why):
    assert h.command(SET, ATTITUDE, interval, param3) == DENIED, why
    assert rates(h)["ATTITUDE"] == 5.0


@pytest.mark.parametrize("msgid", [12345, 65535, 70000])
def test_set_message_interval_for_a_message_we_cannot_produce_is_denied(h, msgid):
    assert h.command(SET, msgid, 100_000) == DENIED


@pytest.mark.parametrize("interval", [1, 999, 1000, 2999])
def test_set_message_interval_faster_than_the_loop_allows_is_denied_with_a_statustext(h, interval):
    """1..999 us count as 1 ms; the cap is 1250 / SCHED_LOOP_RATE (400) = 3 ms."""
    mark = h.mark()
    assert h.command(SET, ATTITUDE, interval) == DENIED
    text = "".join(h.texts(mark))  # STATUSTEXT carries 50 characters: longer texts come in chunks
    assert text == f"Requested rate for message ID {ATTITUDE} too fast. Increase SCHED_LOOP_RATE"
    assert rates(h)["ATTITUDE"] == 5.0


def test_set_message_interval_at_the_loop_cap_is_accepted(h):
    assert h.command(SET, ATTITUDE, 3000) == ACCEPTED
    assert interval_us(h, ATTITUDE) == (ACCEPTED, (ATTITUDE, 3000))


def test_set_message_interval_longer_than_60_s_is_clamped_to_60_s(h):
    assert h.command(SET, ATTITUDE, 600e6) == ACCEPTED
    assert interval_us(h, ATTITUDE) == (ACCEPTED, (ATTITUDE, 60_000_000))


def test_set_message_interval_is_denied_on_a_no_stream_override_channel(tmp_path):
    h = no_override_harness(tmp_path)
    assert h.command(SET, ATTITUDE, 50_000) == DENIED
    assert rates(h)["ATTITUDE"] == 5.0


# --- GET_MESSAGE_INTERVAL and REQUEST_MESSAGE(MESSAGE_INTERVAL) ------------------------------

@pytest.mark.parametrize("command", [GET, M.MAV_CMD_REQUEST_MESSAGE], ids=["get", "request_message_244"])
def test_interval_query_reports_the_scheduled_interval(h, command):
    assert interval_us(h, ATTITUDE, command) == (ACCEPTED, (ATTITUDE, 200_000))
    assert interval_us(h, GLOBAL_POSITION_INT, command) == (ACCEPTED, (GLOBAL_POSITION_INT, 500_000))
    assert interval_us(h, M.MAVLINK_MSG_ID_HEARTBEAT, command) == (ACCEPTED, (M.MAVLINK_MSG_ID_HEARTBEAT, 1_000_000))


@pytest.mark.parametrize("command", [GET, M.MAV_CMD_REQUEST_MESSAGE], ids=["get", "request_message_244"])
def test_interval_query_for_an_unscheduled_message_answers_minus_one(h, command):
    assert interval_us(h, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, command) == \
        (ACCEPTED, (M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, -1))


@pytest.mark.parametrize("command", [GET, M.MAV_CMD_REQUEST_MESSAGE], ids=["get", "request_message_244"])
@pytest.mark.parametrize(("msgid", "reported"), [(12345, 12345), (70000, 65535)])
def test_interval_query_for_a_message_we_cannot_produce_answers_zero_and_fails(h, command, msgid, reported):
    assert interval_us(h, msgid, command) == (FAILED, (reported, 0))


def test_message_interval_is_sent_before_the_ack(h):
    mark = h.mark()
    h.command(GET, ATTITUDE)
    replies = [m.get_type() for m in h.received[mark:] if m.get_type() in ("MESSAGE_INTERVAL", "COMMAND_ACK")]
    assert replies == ["MESSAGE_INTERVAL", "COMMAND_ACK"]


# --- REQUEST_MESSAGE ------------------------------------------------------------------------

def test_request_message_sends_one_copy_of_a_stopped_message(h):
    assert h.command(SET, ATTITUDE, -1) == ACCEPTED
    mark = h.mark()
    assert h.command(M.MAV_CMD_REQUEST_MESSAGE, ATTITUDE) == ACCEPTED
    h.run(2.0, step=STEP_S)
    assert len(h.of_type("ATTITUDE", mark)) == 1


def test_request_message_for_a_message_we_cannot_produce_fails(h):
    mark = h.mark()
    assert h.command(M.MAV_CMD_REQUEST_MESSAGE, 12345) == FAILED
    h.run(1.0, step=STEP_S)
    assert h.of_type("HEARTBEAT", mark), "the node kept sending"


def test_request_message_autopilot_version_arrives_once(h):
    mark = h.mark()
    assert h.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION) == ACCEPTED
    h.run(2.0, step=STEP_S)
    assert len(h.of_type("AUTOPILOT_VERSION", mark)) == 1


@pytest.mark.parametrize(("param1", "result", "copies"), [(1, ACCEPTED, 1), (0, FAILED, 0), (2, FAILED, 0)])
def test_request_autopilot_capabilities_needs_param1_one(h, param1, result, copies):
    mark = h.mark()
    assert h.command(M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, param1) == result
    h.run(1.0, step=STEP_S)
    assert len(h.of_type("AUTOPILOT_VERSION", mark)) == copies
    assert h.of_type("HEARTBEAT", mark), "the node kept sending"


def test_autopilot_version_request_message_pushes_autopilot_version(h):
    mark = h.mark()
    h.send(M.MAVLink_autopilot_version_request_message(*h_target(h)))
    h.run(1.0, step=STEP_S)
    assert len(h.of_type("AUTOPILOT_VERSION", mark)) == 1


def test_available_modes_on_a_spent_radio_budget_are_queued_not_lost(tmp_path):
    """REQUEST_MESSAGE(AVAILABLE_MODES) on a 57 600-baud link: a dozen modes at once are more than
    its 100 ms of budget; every mode still arrives, after the ACK, as it refills (outbox.py)."""
    h = Harness(tmp_path, config={"channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0",
                                                "bandwidth": 5760}]})
    h.run(2.0)  # the default streams run meanwhile
    mark = h.mark()
    h.command(M.MAV_CMD_REQUEST_MESSAGE, 435, 0)  # its ACK may itself wait for the budget
    h.run(5.0)
    # the harness's dialect does not know AVAILABLE_MODES (435): pymavlink names it UNKNOWN_435
    answers = [m for m in h.received[mark:] if m.get_type() in ("COMMAND_ACK", "UNKNOWN_435")]
    acks = [m for m in answers if m.get_type() == "COMMAND_ACK" and m.command == M.MAV_CMD_REQUEST_MESSAGE]
    got = [m for m in answers if m.get_type() == "UNKNOWN_435"]
    assert acks and acks[0].result == M.MAV_RESULT_ACCEPTED and answers.index(acks[0]) < answers.index(got[0])
    assert len(got) == len(h.node.vehicle.modes), "every mode, none lost"
    assert h.channel.snapshot()["replies_dropped"] == 0


# --- every message ArduPilot maps (issue 27) ---------------------------------------------------

# the 14 of the 36 Cockpit asks for at connect that were DENIED before issue 27
COCKPIT_DENIED_BEFORE = ("SCALED_IMU3", "SCALED_PRESSURE2", "SCALED_PRESSURE3", "GPS_RTK", "GPS2_RAW", "GPS2_RTK",
                         "PID_TUNING", "RANGEFINDER", "DISTANCE_SENSOR", "GIMBAL_DEVICE_ATTITUDE_STATUS",
                         "OPTICAL_FLOW", "MAG_CAL_REPORT", "MAG_CAL_PROGRESS", "PARAM_VALUE")


@pytest.mark.parametrize("name", COCKPIT_DENIED_BEFORE)
def test_set_message_interval_is_accepted_for_every_message_cockpit_asks_for(h, name):
    msgid = getattr(M, f"MAVLINK_MSG_ID_{name}")
    assert h.command(SET, msgid, 200_000) == ACCEPTED
    assert interval_us(h, msgid) == (ACCEPTED, (msgid, 200_000))


def test_a_mapped_message_without_a_producer_is_accepted_and_nothing_of_it_is_sent(h):
    """As an ArduPilot build without that sensor: ACCEPTED, the schedule kept, no frame."""
    assert h.command(SET, M.MAVLINK_MSG_ID_GPS2_RAW, 100_000) == ACCEPTED
    assert h.command(SET, ATTITUDE, 100_000) == ACCEPTED  # the positive control, same window
    got = rates(h)
    assert "GPS2_RAW" not in got and got["ATTITUDE"] == 10.0


def test_an_id_ardupilot_does_not_map_is_still_denied(h):
    assert h.command(SET, M.MAVLINK_MSG_ID_LOG_DATA, 100_000) == DENIED
    assert h.command(SET, M.MAVLINK_MSG_ID_SCALED_IMU3, 100_000) == ACCEPTED


def test_request_message_flight_information_is_answered_with_the_arming_time(h):
    mark = h.mark()
    assert h.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_FLIGHT_INFORMATION) == ACCEPTED
    h.run(0.5, step=STEP_S)
    (before,) = h.of_type("FLIGHT_INFORMATION", mark)
    assert before.arming_time_utc == 0 and before.takeoff_time_utc == 0
    assert h.arm() == ACCEPTED
    armed_us = h.node.time_usec(h.t)
    h.run(0.5, step=STEP_S)
    mark = h.mark()
    assert h.command(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_FLIGHT_INFORMATION) == ACCEPTED
    h.run(0.5, step=STEP_S)
    (after,) = h.of_type("FLIGHT_INFORMATION", mark)
    assert abs(after.arming_time_utc - armed_us) <= 100_000  # microseconds since boot, as ArduPilot


@pytest.fixture
def companion(tmp_path) -> Harness:
    h = Harness(tmp_path, vehicle="companion")
    h.run(1.0, step=STEP_S)
    return h


def test_a_companion_streams_its_heartbeat_and_no_vehicle_telemetry(companion):
    got = rates(companion)
    assert got.get("HEARTBEAT") == 1.0  # the positive control
    assert set(got) == {"HEARTBEAT"}, got
    (hb, *_) = companion.of_type("HEARTBEAT")
    assert (hb.type, hb.autopilot, hb.base_mode, hb.system_status) == (
        M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_AUTOPILOT_INVALID, 0, M.MAV_STATE_ACTIVE)


def test_a_companion_sends_its_system_time_only_to_a_client_that_asks(companion):
    assert companion.command(SET, M.MAVLINK_MSG_ID_SYSTEM_TIME, 500_000) == ACCEPTED
    assert rates(companion)["SYSTEM_TIME"] == 2.0


def test_a_companion_refuses_vehicle_telemetry_it_never_has(companion):
    for name in ("GPS_RAW_INT", "ATTITUDE", "BATTERY_STATUS", "HOME_POSITION", "FLIGHT_INFORMATION"):
        msgid = getattr(M, f"MAVLINK_MSG_ID_{name}")
        assert companion.command(SET, msgid, 100_000) == DENIED, name
        assert companion.command(M.MAV_CMD_REQUEST_MESSAGE, msgid) == FAILED, name
    assert "GPS_RAW_INT" not in rates(companion)
