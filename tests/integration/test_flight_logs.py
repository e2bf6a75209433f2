"""Flight logs through the real daemon: the simulated copter's DataFlash log of a flight (arm,
take off, land), listed and downloaded with the MAVLink log protocol and over FTP by pymavlink
clients, read by DFReader; requests while armed refused with ArduPilot's text."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from pymavlink import DFReader

from .helpers import VEHICLE, M, is_ack, is_type, measure_rates, pump, udp_channel, udp_url, wait_for

COPTER_GUIDED, COPTER_LAND = 4, 9
TAKEOFF_M = 3.0


def log_dir(d) -> Path:
    return Path(d.config.state_dir) / d.config.flight_logs.dir


def ack(c, send, command: int, timeout: float = 3.0) -> int:
    mark = c.mark()
    send()
    got = wait_for(c, is_ack(command), timeout=timeout, since=mark)
    assert got is not None, f"no COMMAND_ACK for {command}"
    return got.msg.result


def fly(c) -> None:
    """Arm in GUIDED, take off to TAKEOFF_M, land; returns once the copter has disarmed itself."""
    assert ack(c, lambda: c.command_long(M.MAV_CMD_DO_SET_MODE, 1, COPTER_GUIDED), M.MAV_CMD_DO_SET_MODE) == 0
    assert ack(c, lambda: c.command_long(M.MAV_CMD_COMPONENT_ARM_DISARM, 1), M.MAV_CMD_COMPONENT_ARM_DISARM) == 0
    assert ack(c, lambda: c.command_long(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, TAKEOFF_M),
               M.MAV_CMD_NAV_TAKEOFF) == 0
    high = wait_for(c, lambda r: r.type == "GLOBAL_POSITION_INT" and r.msg.relative_alt >= (TAKEOFF_M - 0.2) * 1000,
                    timeout=20.0)
    assert high is not None, "the copter did not reach its takeoff altitude"
    assert ack(c, lambda: c.command_long(M.MAV_CMD_DO_SET_MODE, 1, COPTER_LAND), M.MAV_CMD_DO_SET_MODE) == 0
    landed = wait_for(c, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE
                      and not r.msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, timeout=40.0, since=c.mark())
    assert landed is not None, "the copter did not land and disarm"


def finished_log(d, timeout: float = 10.0) -> Path:
    """The one log, once it is finished (its size no longer changes and its start time is stamped)."""
    deadline = time.monotonic() + timeout
    last = None
    while time.monotonic() < deadline:
        logs = sorted(log_dir(d).glob("*.BIN"))
        if len(logs) == 1:
            size = logs[0].stat().st_size
            if size == last and abs(logs[0].stat().st_mtime - time.time()) > 3.0:
                return logs[0]
            last = size
        time.sleep(0.5)
    raise AssertionError(f"no finished log in {log_dir(d)}: {list(log_dir(d).glob('*'))}")


def request_list(c) -> list:
    mark = c.mark()
    c.send(M.MAVLink_log_request_list_message(*VEHICLE, 0, 0xFFFF))
    first = wait_for(c, is_type("LOG_ENTRY", VEHICLE), since=mark)
    assert first is not None
    pump([c], 0.3)
    return [r.msg for r in c.since(mark, "LOG_ENTRY")]


def download(c, log_id: int, size: int, timeout: float = 20.0) -> bytes:
    """As MAVProxy: ask for everything, then for the gaps, until a short chunk ends it."""
    got: dict[int, bytes] = {}
    mark = c.mark()
    c.send(M.MAVLink_log_request_data_message(*VEHICLE, log_id, 0, 0xFFFFFFFF))
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        pump([c], 0.2)
        for r in c.since(mark, "LOG_DATA"):
            got[r.msg.ofs] = bytes(r.msg.data[:r.msg.count])
        mark = c.mark()
        have = sum(len(v) for v in got.values())
        if have >= size and any(len(v) < 90 for v in got.values()):
            break
        missing = [ofs for ofs in range(0, size, 90) if ofs not in got]
        if missing:
            c.send(M.MAVLink_log_request_data_message(*VEHICLE, log_id, missing[0], 90 * 20))
    c.send(M.MAVLink_log_request_end_message(*VEHICLE))
    return b"".join(got[ofs] for ofs in sorted(got))


@pytest.mark.slow
def test_a_simulated_flight_leaves_a_log_with_the_flight_that_downloads_byte_for_byte(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    [entry] = request_list(c)
    assert (entry.id, entry.num_logs) == (0, 0)  # nothing logged before the flight
    fly(c)
    path = finished_log(d)
    reader = DFReader.DFReader_binary(str(path))
    types: dict[str, int] = {}
    alts = []
    while (m := reader.recv_match()) is not None:
        types[m.get_type()] = types.get(m.get_type(), 0) + 1
        if m.get_type() == "GPS":
            alts.append(m.Alt)
    assert {"FMT", "FMTU", "PARM", "MODE", "MSG", "GPS", "ATT", "BAT", "CTUN"} <= set(types)
    home_alt = d.config.vehicle.home.alt
    assert max(alts) >= home_alt + TAKEOFF_M - 0.3
    assert min(alts) <= home_alt + 0.5
    data = path.read_bytes()
    [entry] = request_list(c)
    assert (entry.id, entry.num_logs, entry.last_log_num, entry.size) == (1, 1, 1, len(data))
    assert abs(entry.time_utc - path.stat().st_mtime) <= 1
    assert download(c, 1, len(data)) == data


def test_log_requests_while_armed_get_one_disarm_text_and_no_entries(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    assert ack(c, lambda: c.command_long(M.MAV_CMD_COMPONENT_ARM_DISARM, 1), M.MAV_CMD_COMPONENT_ARM_DISARM) == 0
    mark = c.mark()
    for _ in range(3):
        c.send(M.MAVLink_log_request_list_message(*VEHICLE, 0, 0xFFFF))
    text = wait_for(c, lambda r: r.type == "STATUSTEXT" and r.msg.text == "Disarm for log download", since=mark)
    assert text is not None
    c.command_long(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)  # a positive control
    assert wait_for(c, is_type("AUTOPILOT_VERSION", VEHICLE), since=mark) is not None
    pump([c], 0.3)
    assert c.since(mark, "LOG_ENTRY") == []
    assert len([r for r in c.since(mark, "STATUSTEXT") if r.msg.text == "Disarm for log download"]) == 1
    assert ack(c, lambda: c.command_long(M.MAV_CMD_COMPONENT_ARM_DISARM, 0), M.MAV_CMD_COMPONENT_ARM_DISARM) == 0
    assert request_list(c)  # disarmed: answered
    assert d.status()["vehicles"]


def test_a_download_on_a_radio_link_leaves_telemetry_its_rates(daemon, client):
    """A 115 200 baud radio (11 520 bytes/s): the log takes at most half the link, the streams
    keep their rates while it downloads, and the download does progress (the positive control)."""
    d = daemon({"channels": [udp_channel("radio", bandwidth=11520)]})
    logs = log_dir(d)
    logs.mkdir(parents=True, exist_ok=True)
    (logs / "00000001.BIN").write_bytes(os.urandom(300_000))
    c = client(udp_url(d.port("radio")))
    c.heartbeat()
    pump([c], 1.0)
    kinds = ("ATTITUDE", "GLOBAL_POSITION_INT", "SYS_STATUS")
    before = measure_rates({"c": c}, {"c": kinds}, 3.0)
    mark = c.mark()
    c.send(M.MAVLink_log_request_data_message(*VEHICLE, 1, 0, 0xFFFFFFFF))
    during = measure_rates({"c": c}, {"c": kinds}, 4.0)
    chunks = c.since(mark, "LOG_DATA")
    log_bytes_per_s = sum(r.msg.count for r in chunks) / 4.0
    assert log_bytes_per_s >= 1500, f"the download did not progress: {log_bytes_per_s:.0f} B/s"
    assert log_bytes_per_s * (122 / 90) <= 11520 / 2 * 1.25  # at most half the link, frames included
    for kind in kinds:
        assert during[("c", kind)] >= 0.8 * before[("c", kind)], (kind, before, during)
    assert [r.msg.ofs for r in chunks] == sorted(r.msg.ofs for r in chunks)  # in order, none lost


def test_hostile_requests_get_nothing_or_an_empty_chunk_and_erase_keeps_nothing(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    logs = log_dir(d)
    logs.mkdir(parents=True, exist_ok=True)
    for n in (1, 2):
        (logs / f"0000000{n}.BIN").write_bytes(b"\xa3\x95" * 100)
    c = client(udp_url(d.port("gcs")))
    c.heartbeat()
    mark = c.mark()
    for log_id, ofs, count in ((0, 0, 90), (65535, 0, 90), (1, 0xFFFFFFFF, 0xFFFFFFFF), (2, 10, 0)):
        c.send(M.MAVLink_log_request_data_message(*VEHICLE, log_id, ofs, count))
    c.send(M.MAVLink_log_request_list_message(*VEHICLE, 5, 2))  # start after end: nothing to list
    # each request above replaced the one before it (they all arrive before a send pass); a
    # good one, last, is served
    c.send(M.MAVLink_log_request_data_message(*VEHICLE, 2, 150, 90))
    got = wait_for(c, lambda r: r.type == "LOG_DATA" and r.msg.ofs == 150, since=mark)
    assert got is not None and (got.msg.id, got.msg.count) == (2, 50)
    pump([c], 0.3)
    assert [(r.msg.id, r.msg.ofs, r.msg.count) for r in c.since(mark, "LOG_DATA")] == [(2, 150, 50)]
    assert c.since(mark, "LOG_ENTRY") == []
    c.send(M.MAVLink_log_erase_message(*VEHICLE))
    [entry] = request_list(c)
    assert (entry.id, entry.num_logs) == (0, 0) and list(logs.glob("*.BIN")) == []
    assert d.status()["counters"]["logs_erased"] == 2
