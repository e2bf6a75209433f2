"""An uploaded plan is written off the event loop and its MISSION_ACK waits until the file is
durable (services/planwriter.py), through the real vehicle node inside a running loop."""

from __future__ import annotations

import asyncio
import threading

from pymavlink.dialects.v20 import ardupilotmega as M
from vehicle_harness import GCS, Harness

from gcsd.atomic import write_atomic
from gcsd.vehicle.mission import wpl

WP = M.MAV_CMD_NAV_WAYPOINT
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


def _upload(h: Harness, count: int) -> None:
    h.send(M.MAVLink_mission_count_message(h.node.sysid, 1, count, M.MAV_MISSION_TYPE_MISSION))
    for seq in range(count):
        h.send(M.MAVLink_mission_item_int_message(h.node.sysid, 1, seq, REL, WP, 0, 1, 0, 0, 0, 0,
                                                  -353632620 + seq, 1491652370, 10.0, M.MAV_MISSION_TYPE_MISSION))


def _acks(h: Harness, mark: int) -> list:
    return [m for m in h.of_type("MISSION_ACK", mark) if m.mission_type == M.MAV_MISSION_TYPE_MISSION]


async def _until(predicate, timeout_s: float = 5.0) -> bool:
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    while loop.time() < deadline:
        if predicate():
            return True
        await asyncio.sleep(0.005)
    return False


def test_the_ack_of_an_upload_waits_for_the_plan_to_be_on_disk(tmp_path):
    h = Harness(tmp_path)
    writer = h.node.plans.writer
    on_disk = threading.Event()
    go = threading.Event()

    def slow_write(path, text):
        go.wait(5.0)
        write_atomic(path, text)
        on_disk.set()

    writer.write = slow_write  # the disk, slow: a test double for the fsync

    async def main() -> None:
        mark = h.mark()
        _upload(h, 3)
        assert _acks(h, mark) == [], "no ACK before the plan is durable"
        assert h.node.plans.mission.count() == 3  # adopted in memory meanwhile
        go.set()
        assert await _until(lambda: bool(_acks(h, mark)))
        assert on_disk.is_set()
        h.node.send_pass(h.channel, h.t)
        acks = _acks(h, mark)
        assert acks and all(a.type == M.MAV_MISSION_ACCEPTED for a in acks) and acks[0].target_system == GCS[0]

    asyncio.run(main())
    assert len(wpl.loads((tmp_path / "state" / "mission.waypoints").read_text())) == 3
    writer.close()


def test_a_failed_write_keeps_the_previous_plan_and_answers_error(tmp_path):
    h = Harness(tmp_path)
    writer = h.node.plans.writer

    def failing_write(path, text):
        raise OSError(28, "No space left on device")

    async def main() -> None:
        _upload(h, 2)
        assert await _until(lambda: bool(_acks(h, 0)))
        writer.write = failing_write
        mark = h.mark()
        _upload(h, 4)
        assert await _until(lambda: bool(_acks(h, mark)))
        h.node.send_pass(h.channel, h.t)
        assert {a.type for a in _acks(h, mark)} == {M.MAV_MISSION_ERROR}
        assert h.node.plans.mission.count() == 2, "the previous plan is in force"
        assert any("not saved: No space left on device" in t for t in h.texts(mark))

    asyncio.run(main())
    writer.close()
