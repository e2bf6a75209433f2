"""Capture through the real daemon (a companion computer): a fake flight controller that behaves
as ArduPilot's AP_Logger_MAVLink streams its DataFlash log over UDP, losing 10 % of its blocks
on the way, pausing mid-log and rebooting; the files gcsd keeps are the flight controller's logs
byte for byte, DFReader reads them, and `gcsd status` counts what happened."""

from __future__ import annotations

import random
import time
from pathlib import Path

import pytest
from pymavlink import DFReader

from fake_logger_fc import FakeLoggerFC
from gcsd.payloads.logs.simlog import FlightRecorder
from gcsd.vehicle.sim.state import VehicleState

from .helpers import M, pump, udp_channel, udp_url, wait_for

COMPANION = (1, 191)
FC, FC_LOG = (1, 1), 155
TICK_S = 0.005


def dataflash_source(seconds: float) -> bytes:
    s = VehicleState(lat=-35.36, lon=149.16, alt_amsl_m=584.0, home_lat=-35.36, home_lon=149.16, home_alt_m=584.0)
    rec = FlightRecorder({0: "STABILIZE"})
    out = [rec.start(0.0, 0, 1.764e9, s, [(f"P{i}", float(i), 0.0) for i in range(300)], ["fake FC"])]
    t = 0.0
    while t < seconds:
        t += 0.01
        s.alt_amsl_m = 584.0 + t
        out.append(rec.sample(t, int(t * 1e6), 1.764e9 + t, s))
    return b"".join(out)


class FlightController:
    """The fake AP_Logger_MAVLink behind a real pymavlink UDP connection."""

    def __init__(self, c, seed: int = 7) -> None:
        self.c, self.fc, self.rng = c, FakeLoggerFC(), random.Random(seed)
        self.lost = self.sent = 0
        self.last_heartbeat = 0.0
        self.mark = 0

    def run(self, seconds: float, source: bytearray | None = None, bytes_per_s: int = 30_000) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            now = time.monotonic()
            if now - self.last_heartbeat >= 1.0:
                self.last_heartbeat = now
                self.c.mav.srcComponent = FC[1]
                self.c.send(M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA,
                                                        0, 0, 3, 3))
            pump([self.c], TICK_S)
            for r in self.c.since(self.mark, "REMOTE_LOG_BLOCK_STATUS"):
                if (r.msg.target_system, r.msg.target_component) in (FC, (FC[0], FC_LOG)):
                    self.fc.handle_status(r.msg.seqno, r.msg.status, r.src, time.monotonic())
            self.mark = self.c.mark()
            if source:
                n = min(len(source), int(bytes_per_s * TICK_S))
                self.fc.write(bytes(source[:n]))
                del source[:n]
            for seqno, data in self.fc.poll(time.monotonic()):
                if self.rng.random() < 0.10:
                    self.lost += 1
                    continue
                self.sent += 1
                self.c.mav.srcComponent = FC_LOG
                self.c.send(M.MAVLink_remote_log_data_block_message(*self.fc.client, seqno, data))


@pytest.mark.slow
def test_a_streamed_log_is_captured_byte_for_byte_through_loss_a_pause_and_a_reboot(daemon, client):
    d = daemon({"vehicle": {"type": "companion"}, "channels": [udp_channel("fc"), udp_channel("gcs")],
                "flight_logs": {"capture": True, "channels": ["fc"]}})
    fc = FlightController(client(udp_url(d.port("fc")), sysid=FC[0], compid=FC[1]))
    fc.run(2.0)  # its HEARTBEAT: gcsd asks for a START
    assert fc.fc.streaming and fc.fc.client == COMPANION
    first = bytearray(dataflash_source(40.0))
    fc.run(2.0, first)
    fc.run(3.0)  # a pause: nothing to log
    fc.run(3.0, first)
    assert not first and fc.fc.dropped_bytes == 0 and fc.lost > 0
    fc.run(1.0)
    log1 = fc.fc.logged
    fc.fc.reboot()
    second = bytearray(dataflash_source(20.0))
    fc.run(2.5)  # gcsd's next START (within a second of the silence) begins a new log
    assert fc.fc.streaming and fc.fc.starts == 2
    fc.run(3.0, second)
    fc.run(1.5)
    log2 = fc.fc.logged
    logs = sorted((Path(d.config.state_dir) / "logs").glob("*.BIN"))
    assert [p.name for p in logs] == ["00000001.BIN", "00000002.BIN"]
    assert logs[0].read_bytes() == log1 and logs[1].read_bytes() == log2
    for path in logs:
        reader = DFReader.DFReader_binary(str(path))
        kinds = set()
        while (m := reader.recv_match()) is not None:
            kinds.add(m.get_type())
        assert {"FMT", "PARM", "GPS", "ATT"} <= kinds
    counters = d.status()["counters"]
    assert counters["logs_capture_logs"] == 2 and counters["logs_capture_recovered"] > 0
    # served by the companion's own component; a request for component 0 is the flight
    # controller's (same sysid) and gets nothing from the companion
    gcs = client(udp_url(d.port("gcs")))
    gcs.heartbeat()
    mark = gcs.mark()
    gcs.send(M.MAVLink_log_request_list_message(COMPANION[0], 0, 0, 0xFFFF))
    beat = wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == COMPANION, timeout=3.0, since=mark)
    assert beat is not None  # the companion is alive and talking to this station
    pump([gcs], 0.5)
    assert gcs.since(mark, "LOG_ENTRY") == []
    mark = gcs.mark()
    gcs.send(M.MAVLink_log_request_list_message(*COMPANION, 0, 0xFFFF))
    assert wait_for(gcs, lambda r: r.type == "LOG_ENTRY" and r.msg.id == 2, since=mark) is not None
    pump([gcs], 0.3)
    entries = [r.msg for r in gcs.since(mark, "LOG_ENTRY")]
    assert [(e.id, e.num_logs, e.size) for e in entries] == [(1, 2, len(log1)), (2, 2, len(log2))]
    assert all(r.src == COMPANION for r in gcs.since(mark, "LOG_ENTRY"))
