"""A serial channel over a PTY pair: the daemon opens the slave side as its serial device, the
test reads and writes the master side with a pymavlink parser."""

from __future__ import annotations

import os
import time
import tty

import pytest

from gcsd.links.scheduler import SERVICE_SHARE

from .helpers import VEHICLE, M, packed, read_fd

GCS = (255, 190)
MAX_FRAME_BYTES = 280  # a MAVLink2 frame: 10 header + 255 payload + 2 CRC + 13 signature


class Pty:
    """The test's end of a serial line: write frames, parse what comes back."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        self.path = os.ttyname(self.slave)
        self.parser = M.MAVLink(None)
        self.parser.robust_parsing = True
        self.raw = bytearray()
        self.msgs: list = []

    def send(self, msg) -> None:
        os.write(self.master, packed(msg, *GCS))

    def read(self, seconds: float) -> int:
        """Read for `seconds`; returns the number of bytes read."""
        chunk = bytearray()
        read_fd(self.master, seconds, chunk)
        self.raw += chunk
        self.msgs += [m for m in self.parser.parse_buffer(bytes(chunk)) or [] if m.get_type() != "BAD_DATA"]
        return len(chunk)

    def wait_for(self, match, timeout: float = 3.0):
        for _ in range(int(timeout / 0.1)):
            found = [m for m in self.msgs if match(m)]
            if found:
                return found[0]
            self.read(0.1)
        return None

    def close(self) -> None:
        for fd in (self.master, self.slave):
            try:
                os.close(fd)
            except OSError:
                pass


@pytest.fixture
def pty():
    p = Pty()
    yield p
    p.close()  # after the daemon (requested later by the test) has stopped


def _attitude_stamps(msgs: list) -> list[tuple[int, int]]:
    """(index in msgs, time_boot_ms) of every ATTITUDE from the vehicle."""
    return [(i, m.time_boot_ms) for i, m in enumerate(msgs) if m.get_type() == "ATTITUDE" and m.get_srcSystem() == 1]


def _serial_daemon(daemon, pty: Pty, **extra):
    return daemon({"channels": [{"name": "radio", "type": "serial", "device": pty.path, **extra}]})


def test_serial_channel_exchanges_heartbeat_and_command(pty, daemon):
    _serial_daemon(daemon, pty, baud=115200)
    pty.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
    hb = pty.wait_for(lambda m: m.get_type() == "HEARTBEAT")
    assert hb is not None
    assert (hb.get_srcSystem(), hb.get_srcComponent()) == VEHICLE
    assert hb.autopilot == M.MAV_AUTOPILOT_ARDUPILOTMEGA

    force = 21196  # skip the pre-arm checks: this is about the serial line, not the checks
    arm = M.MAV_CMD_COMPONENT_ARM_DISARM
    pty.send(M.MAVLink_command_long_message(*VEHICLE, arm, 0, 1, force, 0, 0, 0, 0, 0))
    ack = pty.wait_for(lambda m: m.get_type() == "COMMAND_ACK" and m.command == arm)
    assert ack is not None
    assert ack.result == M.MAV_RESULT_ACCEPTED
    assert (ack.target_system, ack.target_component) == GCS
    armed = pty.wait_for(lambda m: m.get_type() == "HEARTBEAT" and m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
    assert armed is not None


def test_serial_bandwidth_defaults_to_a_tenth_of_the_baud_rate(pty, daemon):
    """Measured on the daemon's own clock: the bytes sent after one ATTITUDE up to a later one,
    over the time between their time_boot_ms stamps, read until those stamps span `seconds`. A
    reader's window is no measure under load: a reader that wakes late counts what was sent
    before or after its window (9083 B in a "3 s" window, once: 9.5 s of a 960 B/s link), and on
    this link ATTITUDE is one message in twenty sharing 960 B/s, one every 0.6-0.85 s, so a fixed
    3 s window can hold only two or three of them (1.4 s apart, once, in a loaded CI run)."""
    baud = 9600
    streams = ("raw_sens", "ext_stat", "rc_chan", "position", "extra1", "extra2", "extra3")
    fast = {name: 50 for name in streams}
    _serial_daemon(daemon, pty, baud=baud, streams=fast)
    pty.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
    pty.send(M.MAVLink_request_data_stream_message(*VEHICLE, M.MAV_DATA_STREAM_ALL, 50, 1))
    seconds = 3.0
    settle_ms = 1000  # past the initial burst of a full token bucket, on the daemon's clock
    deadline = time.monotonic() + 30.0  # generous: the reader's pace is not what is measured
    first = last = None
    while last is None:
        assert time.monotonic() < deadline, f"ATTITUDE never spanned {seconds} s: {_attitude_stamps(pty.msgs)}"
        pty.read(0.2)
        stamped = _attitude_stamps(pty.msgs)
        if not stamped:
            continue
        first = next((i for i, ms in stamped if ms >= stamped[0][1] + settle_ms), None)
        if first is not None:
            last = next((i for i, ms in stamped if ms >= pty.msgs[first].time_boot_ms + seconds * 1000), None)
    span_s = (pty.msgs[last].time_boot_ms - pty.msgs[first].time_boot_ms) / 1000
    sent = sum(len(m.get_msgbuf()) for m in pty.msgs[first + 1:last + 1])
    budget = baud / 10
    # the budget is a token bucket holding at most one maximal frame at this rate (SPEC: bandwidth);
    # one more frame for the stamps' millisecond rounding
    rate = sent / span_s
    assert sent <= budget * span_s + 2 * MAX_FRAME_BYTES, f"{rate:.0f} B/s on a {budget:.0f} B/s link"
    assert sent >= budget * span_s * 0.5, f"only {rate:.0f} B/s: the streams ask for more than that"
    assert any(m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1 for m in pty.msgs)


PARAM_VALUE_BYTES = 37  # a MAVLink2 PARAM_VALUE on the wire


@pytest.mark.slow
def test_a_ground_station_fetches_every_parameter_through_a_9600_baud_link(pty, daemon):
    """The default streams want about twice the 960 B/s budget of a 9 600-baud link; the list
    still completes, within its share of the budget (scheduler.ServiceShare: 55 s for 1 000
    values; 83 s before the services' turn went ahead of the streams), while HEARTBEAT and the
    streams keep going (the positive control, in the same window). The station asks as MAVProxy
    does: PARAM_REQUEST_LIST, then PARAM_REQUEST_READ of up to 10 missing indices after each
    second without a new value."""
    _serial_daemon(daemon, pty, baud=9600)
    budget = 960
    pty.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3))
    assert pty.wait_for(lambda m: m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1, 5.0)
    mark, start = len(pty.msgs), time.monotonic()
    pty.send(M.MAVLink_param_request_list_message(*VEHICLE))
    got: dict[int, str] = {}
    count, seen, last_new = None, mark, start
    deadline = start + 1.3 * 1000 * PARAM_VALUE_BYTES / (SERVICE_SHARE * budget)  # 75 s; 58 s at the share
    while (count is None or len(got) < count) and time.monotonic() < deadline:
        pty.read(0.1)
        for m in pty.msgs[seen:]:
            if m.get_type() == "PARAM_VALUE" and m.get_srcSystem() == 1 and m.param_index not in got:
                count, got[m.param_index], last_new = m.param_count, m.param_id, time.monotonic()
        seen = len(pty.msgs)
        if count is not None and time.monotonic() - last_new > 1.0:
            for i in [i for i in range(count) if i not in got][:10]:
                pty.send(M.MAVLink_param_request_read_message(*VEHICLE, b"", i))
            last_new = time.monotonic()
    elapsed = time.monotonic() - start
    assert count is not None and len(got) == count, f"{len(got)} of {count} values in {elapsed:.0f} s"
    assert got[0] and len(set(got.values())) == count
    window = pty.msgs[mark:]
    streams = [m for m in window if m.get_type() not in ("PARAM_VALUE", "HEARTBEAT", "STATUSTEXT")]
    stream_bps = sum(len(m.get_msgbuf()) for m in streams) / elapsed
    print(f"{count} parameters at 9600 baud in {elapsed:.1f} s; streams {stream_bps:.0f} B/s")
    assert stream_bps >= 0.7 * (1 - SERVICE_SHARE) * budget, f"the streams' share: {stream_bps:.0f} B/s"
    heartbeats = [m for m in window if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == 1]
    assert len(heartbeats) >= 0.8 * elapsed
    assert {m.get_type() for m in streams} >= {"ATTITUDE", "GLOBAL_POSITION_INT", "SYS_STATUS"}
