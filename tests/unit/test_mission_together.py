"""Mission, fence and rally replaced as one, all or none (gcsd.vehicle.mission.together)."""

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission.effects import Origin, PlanChanged, Text
from gcsd.vehicle.mission.items import MissionItem
from gcsd.vehicle.mission.stores import FenceStore, MissionStore, RallyStore
from gcsd.vehicle.mission.together import write_together
from gcsd.vehicle.mission.transfer import MissionTransfer

HOME = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 0, 1, x=-353632621, y=1491652374, z=584.0)
GCS = Origin(255, 190, "gcs")


def waypoint(n: int) -> MissionItem:
    return MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, x=-353600000 + n, y=1491600000, z=20.0)


def circle(radius: float) -> MissionItem:
    return MissionItem(M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, M.MAV_FRAME_GLOBAL, 0, 0, radius, x=-353632621, y=1491652374)


def rally(n: int) -> MissionItem:
    return MissionItem(M.MAV_CMD_NAV_RALLY_POINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, x=-353600000 + n, y=1491600000, z=25.0)


class Disk:
    """The stores' saver: records what was written, fails the writes listed in `fail` (1-based,
    counted from the last `writes.clear()`)."""

    def __init__(self, fail=()) -> None:
        self.fail = set(fail)
        self.writes: list[tuple[str, tuple]] = []

    def saver(self, name: str):
        def save(items):
            if len(self.writes) + 1 in self.fail:
                self.writes.append((name, None))
                raise OSError(28, "No space left on device")
            self.writes.append((name, tuple(items)))
        return save


def machines(disk: Disk, max_fence: int = 100):
    mission = MissionTransfer(MissionStore(700, lambda: HOME, disk.saver("mission")))
    fence = MissionTransfer(FenceStore(max_fence, disk.saver("fence")))
    rally_t = MissionTransfer(RallyStore(50, disk.saver("rally")))
    for t, items in ((mission, (HOME, waypoint(1))), (fence, (circle(100.0),)), (rally_t, (rally(1),))):
        assert t.write_plan(items, 0.0)[0] == M.MAV_MISSION_ACCEPTED
    disk.writes.clear()
    return mission, fence, rally_t


def stored(*transfers):
    return [t.store.stored() for t in transfers]


def test_three_plans_are_written_together():
    disk = Disk()
    mission, fence, rally_t = machines(disk)
    new = [(mission, (HOME, waypoint(2), waypoint(3))), (fence, (circle(50.0), circle(70.0))), (rally_t, ())]
    written = write_together(new)
    assert written.result == M.MAV_MISSION_ACCEPTED and written.refused_type is None
    assert stored(mission, fence, rally_t) == [items for _, items in new]
    assert [w[0] for w in disk.writes] == ["mission", "fence", "rally"]
    assert written.outputs == [PlanChanged(M.MAV_MISSION_TYPE_MISSION, 3), PlanChanged(M.MAV_MISSION_TYPE_FENCE, 2),
                               PlanChanged(M.MAV_MISSION_TYPE_RALLY, 0)]


def test_a_refused_fence_leaves_the_mission_and_rally_as_they_were_and_nothing_is_written():
    disk = Disk()
    mission, fence, rally_t = machines(disk)
    before = stored(mission, fence, rally_t)
    written = write_together([(mission, (HOME, waypoint(2))), (fence, (circle(-1.0),)), (rally_t, (rally(2),))])
    assert (written.result, written.refused_type) == (M.MAV_MISSION_ERROR, M.MAV_MISSION_TYPE_FENCE)
    assert written.reason == "Fence: circle at item 0 needs a radius > 0"
    assert stored(mission, fence, rally_t) == before and disk.writes == [] and written.outputs == []


def test_too_many_fence_items_is_no_space_before_anything_is_written():
    disk = Disk()
    mission, fence, rally_t = machines(disk, max_fence=2)
    before = stored(mission, fence, rally_t)
    written = write_together([(mission, (HOME,)), (fence, (circle(1.0),) * 3)])
    assert (written.result, written.refused_type) == (M.MAV_MISSION_NO_SPACE, M.MAV_MISSION_TYPE_FENCE)
    assert stored(mission, fence, rally_t) == before and disk.writes == []
    assert write_together([(mission, (HOME,)), (fence, (circle(1.0),) * 2)]).result == M.MAV_MISSION_ACCEPTED


def test_a_bad_item_is_named_with_its_seq():
    mission, _, _ = machines(Disk())
    bad = MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, x=950_000_000, y=0)
    written = write_together([(mission, (HOME, waypoint(1), bad))])
    assert written.result == M.MAV_MISSION_INVALID_PARAM5_X
    assert written.reason == "Mission item 2: MAV_MISSION_INVALID_PARAM5_X"


def test_a_ground_station_uploading_the_fence_denies_the_whole_write():
    mission, fence, rally_t = machines(Disk())
    before = stored(mission, fence, rally_t)
    fence.mission_count(GCS, 2, 1.0)
    written = write_together([(mission, (HOME, waypoint(5))), (fence, ())])
    assert (written.result, written.refused_type) == (M.MAV_MISSION_DENIED, M.MAV_MISSION_TYPE_FENCE)
    assert stored(mission, fence, rally_t) == before
    fence.tick(10.0)  # the upload times out: the same write is taken (positive control)
    assert write_together([(mission, (HOME, waypoint(5))), (fence, ())]).result == M.MAV_MISSION_ACCEPTED


def test_a_save_that_fails_puts_back_the_plans_already_replaced():
    disk = Disk()
    mission, fence, rally_t = machines(disk)
    disk.fail = {3}  # mission written, fence written, rally's write fails
    before = stored(mission, fence, rally_t)
    written = write_together([(mission, (HOME, waypoint(7))), (fence, (circle(9.0),)), (rally_t, (rally(9),))])
    assert (written.result, written.refused_type) == (M.MAV_MISSION_ERROR, M.MAV_MISSION_TYPE_RALLY)
    assert written.reason == "Rally not saved: No space left on device"
    assert stored(mission, fence, rally_t) == before
    # on disk: the new mission and fence, the failed rally, then the old fence and mission again
    assert [w[0] for w in disk.writes] == ["mission", "fence", "rally", "fence", "mission"]
    assert disk.writes[3][1] == before[1] and disk.writes[4][1] == before[0]
    assert not any(isinstance(o, PlanChanged) for o in written.outputs)


def test_when_putting_back_fails_too_memory_still_holds_the_old_plans_and_it_is_told():
    disk = Disk()
    mission, fence, rally_t = machines(disk)
    disk.fail = {2, 3}  # the fence's write fails, then so does putting the mission back
    before = stored(mission, fence, rally_t)
    written = write_together([(mission, (HOME, waypoint(7))), (fence, (circle(9.0),))])
    assert written.result == M.MAV_MISSION_ERROR and stored(mission, fence, rally_t) == before
    assert [o.text for o in written.outputs if isinstance(o, Text)] == [
        "Fence not saved: No space left on device", "Mission not put back on disk: No space left on device"]
