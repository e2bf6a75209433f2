"""The camera component's service with a fake context and a float `now`: its HEARTBEAT every second on
each link (from compid 100, MAV_TYPE_CAMERA, MAV_AUTOPILOT_INVALID), the deadline it asks for, a
photo written and announced from two components, and its bounded outbox."""

from __future__ import annotations

from types import SimpleNamespace

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.payloads.camera.jpeg import read_position
from gcsd.payloads.camera.service import CAMERA_COMPID, HEARTBEAT_INTERVAL_S, OUTBOX_MAX, CameraService
from gcsd.vehicle.sim.state import VehicleState


class FakeChannel:
    def __init__(self, index: int) -> None:
        self.index = index
        self.sent: list[tuple[str, int, object]] = []  # (type, from compid, message)

    def send_message(self, msg, sysid: int, compid: int) -> bool:
        self.sent.append((msg.get_type(), compid, msg))
        return True


class FakeContext:
    def __init__(self, channels) -> None:
        self.channels = channels
        self.sysid, self.compid = 1, 1
        self.state = VehicleState(lat=-35.0, lon=149.0, alt_amsl_m=650.0, home_lat=-35.0, home_lon=149.0,
                                  home_alt_m=600.0)
        self.woken: list[int] = []

    def wake(self, channel) -> None:
        self.woken.append(channel.index)

    def time_boot_ms(self, now: float) -> int:
        return int(now * 1000)

    def time_usec(self, now: float) -> int:
        return int(now * 1e6)

    def wall(self) -> float:
        return 1.8e9

    def now(self) -> float:
        return 0.0


def request(command: int, *params: float, now: float = 1.0, channel=None):
    inc = SimpleNamespace(now=now, channel=channel, sender=(255, 190))
    p = [*params, 0, 0, 0, 0, 0, 0, 0][:7]
    return SimpleNamespace(command=command, params=tuple(p[:4]), param1=p[0], param2=p[1], param3=p[2],
                           param4=p[3], x=p[4], y=p[5], z=p[6], inc=inc)


def test_the_camera_heartbeats_every_second_on_each_link_and_says_when_next(tmp_path):
    channels = [FakeChannel(0), FakeChannel(1)]
    svc = CameraService(FakeContext(channels), tmp_path, now=0.0)
    assert svc.pending(channels[0], 10.0, None) == 10.0 + HEARTBEAT_INTERVAL_S
    assert svc.pending(channels[0], 10.5, None) == 11.0  # not due yet: nothing, same deadline
    assert svc.pending(channels[1], 10.5, None) == 11.5  # each link its own phase
    assert svc.pending(channels[0], 11.0, None) == 12.0
    beats = [(compid, m.type, m.autopilot) for kind, compid, m in channels[0].sent if kind == "HEARTBEAT"]
    assert beats == [(CAMERA_COMPID, M.MAV_TYPE_CAMERA, M.MAV_AUTOPILOT_INVALID)] * 2


def test_a_photo_is_a_file_and_two_messages_on_every_link(tmp_path):
    channels = [FakeChannel(0), FakeChannel(1)]
    ctx = FakeContext(channels)
    svc = CameraService(ctx, tmp_path, now=0.0)
    table = svc.local_components()[CAMERA_COMPID]
    assert table[M.MAV_CMD_IMAGE_START_CAPTURE](request(M.MAV_CMD_IMAGE_START_CAPTURE, 0, 0, 1,
                                                                channel=channels[0])) == M.MAV_RESULT_ACCEPTED
    assert ctx.woken == [0]
    svc.pending(channels[0], 2.0, None)
    svc.pending(channels[1], 2.0, None)
    for ch in channels:
        kinds = [(kind, compid) for kind, compid, _ in ch.sent if kind != "HEARTBEAT"]
        assert kinds == [("CAMERA_IMAGE_CAPTURED", CAMERA_COMPID), ("CAMERA_FEEDBACK", 1)]
    photo = tmp_path / "DCIM" / "100GCSD" / "IMG_00001.JPG"
    assert read_position(photo.read_bytes()) == (-35.0, 149.0, 650.0)
    # a new service on the same directory numbers on
    again = CameraService(ctx, tmp_path, now=0.0)
    assert again.camera.next_index == 2 and again.camera.used_bytes == photo.stat().st_size


def test_an_unwritable_photo_is_reported_failed_and_counted(tmp_path):
    blocker = tmp_path / "DCIM"
    blocker.write_text("a file where the directory should be")
    channels = [FakeChannel(0)]
    svc = CameraService(FakeContext(channels), tmp_path, now=0.0)
    svc.camera.image_start(0, 0, 1)
    svc.pending(channels[0], 1.0, None)
    captured = [m for kind, _, m in channels[0].sent if kind == "CAMERA_IMAGE_CAPTURED"]
    assert [m.capture_result for m in captured] == [0]
    assert svc.counters()["camera_photo_failures"] == 1 and svc.counters()["camera_photos"] == 0


def test_the_outbox_of_a_link_is_bounded(tmp_path):
    channels = [FakeChannel(0)]
    svc = CameraService(FakeContext(channels), tmp_path, now=0.0)
    table = svc.camera_commands()
    for _ in range(OUTBOX_MAX + 10):
        table[M.MAV_CMD_REQUEST_CAMERA_SETTINGS](request(M.MAV_CMD_REQUEST_CAMERA_SETTINGS, 1, channel=channels[0]))
    assert svc.counters()["camera_outbox_dropped"] == 10
    svc.pending(channels[0], 1.0, None)
    assert sum(kind == "CAMERA_SETTINGS" for kind, _, _ in channels[0].sent) == OUTBOX_MAX
