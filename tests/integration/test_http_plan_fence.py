"""A QGroundControl .plan with a geoFence and rallyPoints through the HTTP API, on the real daemon.

The plan (tests/data/qgc/fence_rally.plan, QGC's format) is PUT over HTTP; a pymavlink ground
station on a real UDP socket then downloads MISSION_TYPE_FENCE and MISSION_TYPE_RALLY as QGC
would, and what it gets is compared with the file itself (read here, not through gcsd's
converter): commands, counts, vertex counts, latitudes and longitudes as int32 degE7. A GET gives
back what was PUT, and shows what a ground station uploaded over MAVLink; a bad plan is refused
(422, or 400 for malformed JSON) with nothing of it stored, which the ground station's download
of the old plan shows. The fence put is the one the vehicle's pre-arm check uses.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

from tests.unit.test_http_plan_fence import normalised, qgc_plan

from gcsd.vehicle.mission import wpl
from gcsd.vehicle.mission.items import MissionItem

from .helpers import VEHICLE, M, is_type, udp_url, wait_for
from .http_client import call, poll
from .mission_client import MissionClient
from .test_http_api import GCS_CHANNEL, api  # noqa: F401  (the fixture)

FENCE, RALLY = M.MAV_MISSION_TYPE_FENCE, M.MAV_MISSION_TYPE_RALLY
VERTEX = {True: M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, False: M.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION}
CIRCLE = {True: M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, False: M.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION}


def e7(degrees: float) -> int:
    return round(degrees * 1e7)


def expected_fence(plan: dict) -> list[tuple]:
    """(command, param1, x, y) of each fence item, in the order QGC uploads them."""
    fence = plan["geoFence"]
    out = [(VERTEX[p["inclusion"]], float(len(p["polygon"])), e7(lat), e7(lon))
           for p in fence["polygons"] for lat, lon in p["polygon"]]
    out += [(CIRCLE[c["inclusion"]], float(c["circle"]["radius"]), e7(c["circle"]["center"][0]),
             e7(c["circle"]["center"][1])) for c in fence["circles"]]
    if "breachReturn" in fence:
        out.append((M.MAV_CMD_NAV_FENCE_RETURN_POINT, 0.0, e7(fence["breachReturn"][0]), e7(fence["breachReturn"][1])))
    return out


def expected_rally(plan: dict) -> list[tuple]:
    return [(M.MAV_CMD_NAV_RALLY_POINT, e7(lat), e7(lon), float(alt)) for lat, lon, alt in plan["rallyPoints"]["points"]]


def fence_of(items) -> list[tuple]:
    return [(i.command, i.param1, i.x, i.y) for i in items]


def rally_of(items) -> list[tuple]:
    return [(i.command, i.x, i.y, i.z) for i in items]


def put(url: str, document=None, raw: bytes | None = None):
    status, _, body, _ = call(f"{url}/v1/vehicles/1/mission", "PUT", document, raw=raw,
                              headers={"Content-Type": "application/json"})
    return status, body


def get(url: str) -> dict:
    status, _, body, _ = call(f"{url}/v1/vehicles/1/mission")
    assert status == 200
    return body


def test_a_qgc_plan_with_fence_and_rally_is_what_a_mavlink_ground_station_downloads(api, tmp_path):  # noqa: F811
    d, url, gcs = api
    plan = qgc_plan()
    assert put(url, plan) == (200, {"items": 4, "fence": 12, "rally": 3})
    station = MissionClient(gcs)
    fence = station.download(FENCE)
    assert fence_of(fence) == expected_fence(plan)
    assert [i.param1 for i in fence[:9]] == [5.0] * 5 + [4.0] * 4  # each vertex carries its polygon's count
    assert all(-2**31 <= v < 2**31 for i in fence for v in (i.x, i.y))  # int32 on the wire
    assert rally_of(station.download(RALLY)) == expected_rally(plan)
    mission = station.download(M.MAV_MISSION_TYPE_MISSION)
    assert [i.command for i in mission] == [16, 22, 16, 16, 20]  # home, then the plan's items
    # GET gives back what was PUT (coordinates to the 7 decimals of degE7)
    got = get(url)
    assert normalised(got["geoFence"]) == normalised(plan["geoFence"])
    assert normalised(got["rallyPoints"]) == normalised(plan["rallyPoints"])
    assert [i["params"][4:6] for i in got["mission"]["items"]] == [i["params"][4:6] for i in plan["mission"]["items"]]
    # and the vehicle keeps them: the state directory's files hold the same items
    state = Path(d.config.state_dir)
    assert fence_of(wpl.loads((state / "fence.waypoints").read_text())) == expected_fence(plan)
    assert rally_of(wpl.loads((state / "rally.waypoints").read_text())) == expected_rally(plan)


def test_bad_plans_are_refused_whole_and_the_ground_station_still_downloads_the_old_one(api):  # noqa: F811
    _, url, gcs = api
    good = qgc_plan()
    assert put(url, good)[0] == 200  # positive control: the same daemon takes a good plan

    def bad(change):
        plan = copy.deepcopy(good)
        plan["mission"]["items"] = plan["mission"]["items"][:1]  # a valid new mission rides along
        change(plan)
        return plan

    cases = [
        (bad(lambda p: p["geoFence"]["polygons"][0].update(polygon=[[-35.36, 149.16], [-35.37, 149.17]])),
         "geoFence.polygons[0].polygon: 2 vertices"),
        (bad(lambda p: p["geoFence"]["circles"][1]["circle"].update(radius=0)), "geoFence.circles[1].circle.radius: 0"),
        (bad(lambda p: p["geoFence"]["circles"][1]["circle"].update(radius=-3)), "radius: -3"),
        (bad(lambda p: p["geoFence"]["polygons"][1]["polygon"][2].__setitem__(0, 91.0)), "latitude 91.0 out of -90..90"),
        (bad(lambda p: p["rallyPoints"]["points"][1].__setitem__(1, None)), "rallyPoints.points[1]: None"),
        # valid at the edge, refused by the vehicle's limits (mission.max_fence 100, max_rally 50)
        (bad(lambda p: p["geoFence"]["polygons"][0].update(polygon=[[-35.36 + n * 1e-5, 149.16] for n in range(120)])),
         "geoFence: too many items for the vehicle, at most 100 (mission.max_fence"),
        (bad(lambda p: p["rallyPoints"].update(points=[[-35.36, 149.16, 20]] * 51)),
         "rallyPoints: too many items for the vehicle, at most 50"),
        # refused by the vehicle's mission checks, after the fence and rally passed theirs
        (bad(lambda p: p["mission"]["items"][0]["params"].__setitem__(4, 95.0)), "MAV_MISSION_INVALID_PARAM5_X"),
    ]
    for document, error in cases:
        status, body = put(url, document)
        assert status == 422 and error in body["error"], (error, status, body)
    radius = json.dumps(good).replace('"radius": 42.5', '"radius": 1e999')  # JSON's way to infinity
    assert radius != json.dumps(good)
    status, body = put(url, raw=radius.encode())
    assert status == 422 and "circles[1].circle.radius: inf" in body["error"]
    assert put(url, raw=b'{"fileType": "Plan", "geoFence": NaN}')[0] == 400
    assert put(url, raw=b'{"fileType": "Plan", "geoFence": {')[0] == 400
    # nothing of any of them was stored: the ground station downloads the good plan, whole
    station = MissionClient(gcs)
    assert fence_of(station.download(FENCE)) == expected_fence(good)
    assert rally_of(station.download(RALLY)) == expected_rally(good)
    assert len(station.download(M.MAV_MISSION_TYPE_MISSION)) == 5
    assert call(f"{url}/v1/status")[0] == 200


def test_a_plan_is_refused_with_409_while_a_ground_station_uploads_a_fence(api):  # noqa: F811
    _, url, gcs = api
    mark = gcs.mark()
    gcs.send(M.MAVLink_mission_count_message(*VEHICLE, 3, FENCE))
    assert wait_for(gcs, lambda r: is_type("MISSION_REQUEST", VEHICLE)(r) and r.msg.mission_type == FENCE, since=mark)
    status, body = put(url, qgc_plan())
    assert status == 409 and "uploading" in body["error"]
    assert len(MissionClient(gcs).download(RALLY)) == 0  # nothing of the plan was taken
    gcs.send(M.MAVLink_mission_ack_message(*VEHICLE, M.MAV_MISSION_OPERATION_CANCELLED, FENCE))  # the GCS gives up
    # the UDP datagram and the HTTP request race: taken within 3 s, long before the 8 s upload timeout
    assert poll(lambda: put(url, qgc_plan())[0] == 200, timeout=3.0)
    assert len(MissionClient(gcs).download(RALLY)) == 3


def test_the_plan_survives_a_restart_and_an_empty_geofence_clears_the_fence(daemon, client):
    plan = qgc_plan()
    first = daemon(GCS_CHANNEL)
    assert put(first.http_url(), plan)[0] == 200
    first.stop()
    second = daemon(GCS_CHANNEL)
    url = second.http_url()
    got = get(url)
    assert normalised(got["geoFence"]) == normalised(plan["geoFence"])
    assert normalised(got["rallyPoints"]) == normalised(plan["rallyPoints"])
    # a plan without geoFence and rallyPoints leaves them; an empty one clears them
    partial = {k: v for k, v in plan.items() if k not in ("geoFence", "rallyPoints")}
    assert put(url, partial) == (200, {"items": 4})
    assert normalised(get(url)["geoFence"]) == normalised(plan["geoFence"])
    empty = {**plan, "geoFence": {"version": 2, "polygons": [], "circles": []}, "rallyPoints": {"version": 2, "points": []}}
    assert put(url, empty) == (200, {"items": 4, "fence": 0, "rally": 0})
    gcs = client(udp_url(second.port("gcs")))
    gcs.heartbeat()
    assert wait_for(gcs, is_type("HEARTBEAT", VEHICLE))
    station = MissionClient(gcs)
    assert station.download(FENCE) == [] and station.download(RALLY) == []
    assert len(station.download(M.MAV_MISSION_TYPE_MISSION)) == 5  # positive control: the mission is there


def test_the_vehicle_arms_by_the_fence_of_the_plan(api):  # noqa: F811
    """The fence put over HTTP is the one the vehicle's pre-arm check uses (FENCE_TYPE's polygon bit)."""
    _, url, gcs = api
    assert call(f"{url}/v1/vehicles/1/parameters/FENCE_ENABLE", "PUT", {"value": 1})[0] == 200
    assert put(url, qgc_plan())[0] == 200  # home inside the inclusion zones, outside the exclusions
    assert call(f"{url}/v1/vehicles/1/arm", "POST", {})[0] == 200  # positive control
    assert call(f"{url}/v1/vehicles/1/disarm", "POST", {})[0] == 200
    walled = qgc_plan()
    walled["geoFence"]["circles"][1]["circle"].update(center=[-35.3632621, 149.1652374], radius=20)  # around home
    assert put(url, walled)[0] == 200
    mark = gcs.mark()
    status, _, body, _ = call(f"{url}/v1/vehicles/1/arm", "POST", {})
    assert status == 409 and "COMPONENT_ARM_DISARM" in body["error"]
    text = wait_for(gcs, lambda r: r.type == "STATUSTEXT" and "Fence" in r.msg.text, since=mark)
    assert text and "PreArm: Fence: vehicle outside the polygon fence" in text.msg.text


def test_a_fence_and_rally_points_a_ground_station_uploads_are_what_get_shows(api):  # noqa: F811
    _, url, gcs = api
    plan = qgc_plan()
    frame = M.MAV_FRAME_GLOBAL_INT  # another ground station's choices: its own frame, circles first
    fence = [MissionItem(cmd, frame, 0, 1, p1, x=x, y=y) for cmd, p1, x, y in expected_fence(plan)[:11]]
    fence = fence[9:] + fence[:9]
    points = [MissionItem(cmd, M.MAV_FRAME_GLOBAL, 0, 1, x=x, y=y, z=z) for cmd, x, y, z in expected_rally(plan)]
    station = MissionClient(gcs)
    assert station.upload(fence, FENCE) == M.MAV_MISSION_ACCEPTED
    assert station.upload(points, RALLY) == M.MAV_MISSION_ACCEPTED
    got = get(url)
    del plan["geoFence"]["breachReturn"]  # not uploaded
    assert normalised(got["geoFence"]) == normalised(plan["geoFence"])
    assert normalised(got["rallyPoints"]) == normalised(plan["rallyPoints"])
