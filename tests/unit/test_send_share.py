"""Owed traffic gets through a link whose default streams want more than its byte budget
(scheduler.py, "The pass"; ServiceShare). A serial channel at 9 600 baud has a budget of 960 B/s
(its default `bandwidth`, baud // 10); the copter's default streams want about 2 000 B/s. Before
the services' turn went ahead of the streams, an FTP reply or a STATUSTEXT never went out on such
a link and a parameter list took 83 s; now each is served within its share of the budget while
the streams keep the rest. The vehicle node runs under the channel task's pacing (Harness.serve:
each send pass at the deadline the last one returned) with a float clock."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M
from vehicle_harness import Harness

from gcsd.links.scheduler import SERVICE_SHARE
from gcsd.vehicle.ftp.protocol import Nak, Op, Payload

BAUD = 9600
BUDGET_BPS = BAUD // 10
PARAM_VALUE_BYTES = 37  # a MAVLink2 PARAM_VALUE on the wire


@pytest.fixture
def radio(tmp_path) -> Harness:
    """A copter on one serial channel at 9 600 baud, everything else at its defaults."""
    h = Harness(tmp_path, config={"channels": [{"name": "radio", "type": "serial", "device": "/dev/ttyAMA0",
                                                "baud": BAUD}]})
    assert h.channel.config.bandwidth == BUDGET_BPS
    h.serve(5.0)  # the streams are running and the budget is spent
    return h


def _bytes(msgs) -> int:
    return sum(len(m.get_msgbuf()) for m in msgs)


def test_the_default_streams_want_more_than_the_budget_of_a_9600_baud_link(radio):
    """The premise (and the budget's positive control): the streams alone fill the link."""
    mark, t0 = radio.mark(), radio.t
    radio.serve(10.0)
    sent = radio.received[mark:]
    assert 0.95 * BUDGET_BPS * 10 <= _bytes(sent) <= BUDGET_BPS * 10 + 280
    attitude_hz = len([m for m in sent if m.get_type() == "ATTITUDE"]) / (radio.t - t0)
    assert attitude_hz < 0.6 * radio.channel.config.streams["extra1"], "slower than asked: the link is full"


def test_a_parameter_list_completes_in_bounded_time_and_the_streams_keep_their_share(radio):
    mark, t0 = radio.mark(), radio.t
    count = len(radio.node.params)
    radio.send(M.MAVLink_param_request_list_message(1, 1))
    ideal_s = count * PARAM_VALUE_BYTES / (SERVICE_SHARE * BUDGET_BPS)  # 58 s for 1 000 values
    done = radio.serve(1.15 * ideal_s, until=lambda: len({
        m.param_index for m in radio.of_type("PARAM_VALUE", mark)}) == count)
    elapsed = radio.t - t0
    assert done, f"{len(radio.of_type('PARAM_VALUE', mark))} of {count} values in {elapsed:.0f} s"
    sent = radio.received[mark:]
    streams = [m for m in sent if m.get_type() not in ("PARAM_VALUE", "HEARTBEAT", "STATUSTEXT")]
    assert _bytes(sent) <= BUDGET_BPS * elapsed + 280, "within the budget"
    assert _bytes(streams) >= 0.8 * (1 - SERVICE_SHARE) * BUDGET_BPS * elapsed, "the streams' share"
    assert len(radio.of_type("HEARTBEAT", mark)) >= int(elapsed) - 1, "HEARTBEAT at 1 Hz throughout"
    assert {m.get_type() for m in streams} >= {"ATTITUDE", "GLOBAL_POSITION_INT", "SYS_STATUS", "VFR_HUD"}


def test_a_statustext_goes_out_on_a_full_link(radio):
    """A refused PARAM_SET is answered with its reason; the streams are not slowed for it."""
    read_only = next(e.name for e in radio.node.params.entries() if radio.node.params.definition(e.name).read_only)
    mark = radio.mark()
    radio.set_param(read_only, 3)
    assert radio.serve(2.0, until=lambda: radio.texts(mark)), "no STATUSTEXT within 2 s"
    assert radio.texts(mark) == [f"Param write denied ({read_only})"]
    radio.serve(1.0)  # the positive control: the streams went on in the same window
    assert radio.of_type("PARAM_VALUE", mark) and radio.of_type("ATTITUDE", mark)


class FtpClient:
    """One request at a time, as a ground station does; replies read from what the node sent."""

    def __init__(self, h: Harness) -> None:
        self.h = h
        self.seq = 0
        self.seen = 0

    def request(self, opcode: int, data: bytes = b"", size: int | None = None, offset: int = 0,
                session: int = 0) -> None:
        payload = Payload(self.seq, session, opcode, len(data) if size is None else size, 0, 0, offset, data).pack()
        self.seq += 1
        self.seen = self.h.mark()
        self.h.send(M.MAVLink_file_transfer_protocol_message(0, self.h.node.sysid, 1, list(payload.ljust(251, b"\0"))))

    def replies(self) -> list[Payload]:
        return [Payload.unpack(bytes(m.payload)) for m in self.h.of_type("FILE_TRANSFER_PROTOCOL", self.seen)]

    def answer(self, within_s: float) -> Payload:
        assert self.h.serve(within_s, until=self.replies), f"no FTP reply within {within_s} s"
        return self.replies()[0]


def test_an_ftp_file_is_read_over_a_full_link_while_the_streams_go_on(radio):
    content = bytes(range(256)) * 8  # 2 KiB: 9 packets of a burst
    (radio.node.state_dir / "ftp" / "notes.bin").write_bytes(content)
    ftp = FtpClient(radio)
    mark, t0 = radio.mark(), radio.t
    ftp.request(Op.OPEN_FILE_RO, b"notes.bin")
    opened = ftp.answer(2.0)
    assert opened.opcode == Op.ACK, opened
    ftp.request(Op.BURST_READ_FILE, session=opened.session)
    # the burst is paced by the FTP service itself to a third of the link (ftp/burst.py)
    assert radio.serve(15.0, until=lambda: any(p.opcode == Op.NAK for p in ftp.replies())), "burst unfinished"
    data = bytearray()
    for p in ftp.replies():
        if p.opcode == Op.ACK:
            data[p.offset:p.offset + p.size] = p.data[:p.size]
    assert bytes(data) == content
    assert Nak(ftp.replies()[-1].data[0]) == Nak.EOF
    ftp.request(Op.TERMINATE_SESSION, session=opened.session)
    assert ftp.answer(2.0).opcode == Op.ACK
    elapsed = radio.t - t0
    streams = [m for m in radio.received[mark:] if m.get_type() not in ("FILE_TRANSFER_PROTOCOL", "HEARTBEAT")]
    assert _bytes(streams) >= 0.8 * (1 - SERVICE_SHARE) * BUDGET_BPS * elapsed, "the streams' share"
    assert _bytes(radio.received[mark:]) <= BUDGET_BPS * elapsed + 280, "within the budget"


def test_a_link_without_a_budget_has_no_share(tmp_path):
    """The default UDP channel: no bandwidth, no share; the services just go before the buckets."""
    h = Harness(tmp_path)
    assert h.channel.config.bandwidth is None and h.node.links[0].share is None
    mark = h.mark()
    h.send(M.MAVLink_param_request_list_message(1, 1))
    assert h.serve(2.0, until=lambda: len(h.of_type("PARAM_VALUE", mark)) == len(h.node.params))
    assert h.of_type("ATTITUDE", mark), "and the streams in the same window"


def test_a_mission_goes_up_and_comes_back_over_a_full_link(radio):
    """Item by item, each answer awaited as a ground station does: the items are owed replies and
    go ahead of the streams within the services' share (30 items down in 2.2 s; 5.8 s before,
    when each waited for the streams to leave a whole frame), the streams keeping the rest."""
    items = 30
    mark = radio.mark()
    radio.send(M.MAVLink_mission_count_message(1, 1, items, M.MAV_MISSION_TYPE_MISSION))
    for seq in range(items):
        asked = lambda seq=seq: [m for m in radio.received[mark:] if m.get_type() in (
            "MISSION_REQUEST", "MISSION_REQUEST_INT") and m.seq == seq]
        assert radio.serve(2.0, until=asked), f"item {seq} not asked for within 2 s"
        radio.send(M.MAVLink_mission_item_int_message(1, 1, seq, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                                                      M.MAV_CMD_NAV_WAYPOINT, 0, 1, 0, 0, 0, 0,
                                                      int(-35.36e7) + seq, int(149.16e7), 20.0))
    assert radio.serve(2.0, until=lambda: radio.of_type("MISSION_ACK", mark))
    assert radio.of_type("MISSION_ACK", mark)[-1].type == M.MAV_MISSION_ACCEPTED
    mark, t0 = radio.mark(), radio.t
    radio.send(M.MAVLink_mission_request_list_message(1, 1, M.MAV_MISSION_TYPE_MISSION))
    assert radio.serve(2.0, until=lambda: radio.of_type("MISSION_COUNT", mark))
    assert radio.of_type("MISSION_COUNT", mark)[0].count == items
    for seq in range(items):
        radio.send(M.MAVLink_mission_request_int_message(1, 1, seq, M.MAV_MISSION_TYPE_MISSION))
        got = lambda seq=seq: [m for m in radio.of_type("MISSION_ITEM_INT", mark) if m.seq == seq]
        assert radio.serve(2.0, until=got), f"item {seq} not sent within 2 s"
        assert seq == 0 or got()[0].x == int(-35.36e7) + seq  # item 0 is home, as ArduPilot's
    elapsed = radio.t - t0
    owed = [m for m in radio.received[mark:] if m.get_type() in ("MISSION_COUNT", "MISSION_ITEM_INT", "MISSION_ACK")]
    assert elapsed < 1.5 * _bytes(owed) / (SERVICE_SHARE * BUDGET_BPS), f"{items} items down in {elapsed:.1f} s"
    streams = [m for m in radio.received[mark:] if m not in owed and m.get_type() != "HEARTBEAT"]
    assert _bytes(streams) >= 0.7 * (1 - SERVICE_SHARE) * BUDGET_BPS * elapsed, "the streams' share"
    assert _bytes(radio.received[mark:]) <= BUDGET_BPS * elapsed + 280, "within the budget"


def test_forwarded_frames_that_keep_the_link_short_of_a_frame_do_not_stop_the_streams(radio):
    """An FTP reply waits for a whole frame that never comes: frames forwarded from another link
    (12 kB/s, dropped and counted beyond the budget) take the budget as it refills. The streams
    hold back for the reply at most HOLD_MAX_S (1 s), then go on with what the budget leaves."""
    ftp = FtpClient(radio)
    ftp.request(Op.LIST_DIRECTORY, b"/")
    forwarded = bytes(M.MAVLink_statustext_message(M.MAV_SEVERITY_INFO, b"x" * 50).pack(
        M.MAVLink(None, srcSystem=7, srcComponent=1)))  # from another vehicle, for everyone
    mark = radio.mark()
    for _ in range(500):  # 5 s
        radio.t += 0.01
        radio.channel.tick(radio.t, radio.clock.wall())
        radio.channel.write(forwarded)
        radio.node.send_pass(radio.channel, radio.t)
    late = [m for m in radio.received[mark:] if m.get_srcSystem() == 1 and m.get_type() not in (
        "HEARTBEAT", "FILE_TRANSFER_PROTOCOL")]
    assert late and late[0].get_type() != "STATUSTEXT", "the streams went on"
    assert radio.channel.snapshot()["drops"] > 0, "the forwarded frames did fill the link"
