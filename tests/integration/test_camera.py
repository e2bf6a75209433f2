"""The camera (`vehicle.camera: true`) against the real daemon over UDP with pymavlink: QGroundControl's
camera manager discovery replayed step by step (src/Camera/QGCCameraManager.cc,
VehicleCameraControl.cc), photos as CAMERA_IMAGE_CAPTURED + CAMERA_FEEDBACK + a JPEG whose EXIF
position is where GLOBAL_POSITION_INT put the vehicle at that instant, a mission with
DO_SET_CAM_TRIGG_DIST leaving photos along its route, and the answers of each camera command."""

from __future__ import annotations

import itertools
import math

import pytest

from gcsd.payloads.camera.jpeg import read_position
from gcsd.vehicle.mission.items import MissionItem
from gcsd.vehicle.sim.geo import distance_m, offset

from .helpers import M, wait_for
from .mission_client import MissionClient

QGC = (255, 190)
CAMERA = (1, 100)
AUTOPILOT = (1, 1)
HOME = (-35.363262, 149.165237, 584.0)
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


@pytest.fixture
def camera(daemon, client, tmp_path):
    d = daemon({"vehicle": {"camera": True},
                "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]})
    gcs = client(f"udpout:127.0.0.1:{d.port('gcs')}", *QGC)
    gcs.heartbeat()
    assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == AUTOPILOT)
    return gcs, tmp_path / "state" / "ftp"


def command(gcs, cmd: int, *params: float, target=AUTOPILOT, timeout: float = 3.0):
    mark = gcs.mark()
    gcs.command_long(cmd, *params, target=target)
    r = wait_for(gcs, lambda r: r.type == "COMMAND_ACK" and r.msg.command == cmd and r.src == target, timeout,
                 since=mark)
    return None if r is None else r.msg.result


def requested(gcs, cmd: int, msg: str, *params: float):
    """A request to the camera: its ACK (from the camera) and then the message (from the camera)."""
    mark = gcs.mark()
    assert command(gcs, cmd, *params, target=CAMERA) == M.MAV_RESULT_ACCEPTED
    r = wait_for(gcs, lambda r: r.type == msg and r.src == CAMERA, since=mark)
    assert r is not None, f"no {msg} after {cmd}"
    return r.msg


def test_qgc_camera_manager_discovers_the_camera(camera):
    gcs, _ = camera
    # a camera component's own HEARTBEAT (QGC ignores the autopilot's for camera discovery)
    hb = wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == CAMERA)
    assert hb is not None
    assert (hb.msg.type, hb.msg.autopilot) == (M.MAV_TYPE_CAMERA, M.MAV_AUTOPILOT_INVALID)
    # _requestCameraInfo alternates REQUEST_MESSAGE and the legacy REQUEST_CAMERA_INFORMATION(1)
    info = requested(gcs, M.MAV_CMD_REQUEST_MESSAGE, "CAMERA_INFORMATION", M.MAVLINK_MSG_ID_CAMERA_INFORMATION)
    assert bytes(info.vendor_name).rstrip(b"\0") == b"gcsd" and bytes(info.model_name).rstrip(b"\0") == b"SimCam"
    assert info.flags & M.CAMERA_CAP_FLAGS_CAPTURE_IMAGE and info.flags & M.CAMERA_CAP_FLAGS_CAPTURE_VIDEO
    assert info.cam_definition_uri == ""  # a basic camera: QGC asks for no parameters
    legacy = requested(gcs, M.MAV_CMD_REQUEST_CAMERA_INFORMATION, "CAMERA_INFORMATION", 1)
    assert legacy.flags == info.flags
    # _initWhenReady: settings at 0.5 s, capture status at 1.5 s, storage at 2 s (each with its legacy twin)
    assert requested(gcs, M.MAV_CMD_REQUEST_MESSAGE, "CAMERA_SETTINGS",
                     M.MAVLINK_MSG_ID_CAMERA_SETTINGS).mode_id == M.CAMERA_MODE_IMAGE
    requested(gcs, M.MAV_CMD_REQUEST_CAMERA_SETTINGS, "CAMERA_SETTINGS", 1)
    status = requested(gcs, M.MAV_CMD_REQUEST_MESSAGE, "CAMERA_CAPTURE_STATUS", M.MAVLINK_MSG_ID_CAMERA_CAPTURE_STATUS)
    assert (status.image_status, status.video_status) == (0, 0)
    requested(gcs, M.MAV_CMD_REQUEST_CAMERA_CAPTURE_STATUS, "CAMERA_CAPTURE_STATUS", 1)
    storage = requested(gcs, M.MAV_CMD_REQUEST_MESSAGE, "STORAGE_INFORMATION", M.MAVLINK_MSG_ID_STORAGE_INFORMATION)
    assert storage.status == M.STORAGE_STATUS_READY and storage.total_capacity > 0
    requested(gcs, M.MAV_CMD_REQUEST_STORAGE_INFORMATION, "STORAGE_INFORMATION", 0)
    # takePhoto: IMAGE_START_CAPTURE(0, 0, 1) to the camera's compid
    mark = gcs.mark()
    assert command(gcs, M.MAV_CMD_IMAGE_START_CAPTURE, 0, 0, 1, target=CAMERA) == M.MAV_RESULT_ACCEPTED
    captured = wait_for(gcs, lambda r: r.type == "CAMERA_IMAGE_CAPTURED" and r.src == CAMERA, since=mark)
    feedback = wait_for(gcs, lambda r: r.type == "CAMERA_FEEDBACK" and r.src == AUTOPILOT, since=mark)
    assert captured is not None and feedback is not None
    assert captured.msg.capture_result == 1 and captured.msg.image_index == feedback.msg.img_idx == 1
    assert captured.msg.file_url == "mftp://[;comp=1]/DCIM/100GCSD/IMG_00001.JPG"


def test_photo_exif_and_image_captured_agree_with_global_position_int(camera):
    gcs, ftp = camera
    assert command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 50_000) == \
        M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_DO_SET_MODE, 1, 4) == M.MAV_RESULT_ACCEPTED  # GUIDED
    assert command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 30) == M.MAV_RESULT_ACCEPTED
    assert wait_for(gcs, lambda r: r.type == "GLOBAL_POSITION_INT" and r.msg.relative_alt > 10_000, 30.0)
    target = offset(*HOME[:2], 0.0, 200.0)  # fly east at speed: photos taken on the move
    gcs.send(M.MAVLink_set_position_target_global_int_message(
        0, 1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0b110111111000, round(target[0] * 1e7), round(target[1] * 1e7),
        30, 0, 0, 0, 0, 0, 0, 0, 0))
    assert wait_for(gcs, lambda r: r.type == "GLOBAL_POSITION_INT" and math.hypot(r.msg.vx, r.msg.vy) > 500, 15.0)
    mark = gcs.mark()
    assert command(gcs, M.MAV_CMD_IMAGE_START_CAPTURE, 0, 0, 1, target=CAMERA) == M.MAV_RESULT_ACCEPTED
    captured = wait_for(gcs, lambda r: r.type == "CAMERA_IMAGE_CAPTURED", since=mark)
    assert captured is not None and captured.msg.capture_result == 1
    c = captured.msg
    # the GLOBAL_POSITION_INT nearest in time to the photo (time_boot_ms of the same clock)
    positions = [r.msg for r in gcs.since(mark) if r.type == "GLOBAL_POSITION_INT"]
    positions += [r.msg for r in [wait_for(gcs, lambda r: r.type == "GLOBAL_POSITION_INT", since=gcs.mark())]]
    nearest = min(positions, key=lambda p: abs(p.time_boot_ms - c.time_boot_ms))
    assert abs(nearest.time_boot_ms - c.time_boot_ms) <= 100
    speed = math.hypot(nearest.vx, nearest.vy) / 100
    gap_m = distance_m(c.lat / 1e7, c.lon / 1e7, nearest.lat / 1e7, nearest.lon / 1e7)
    assert gap_m <= 3.0 + speed * abs(nearest.time_boot_ms - c.time_boot_ms) / 1000, (gap_m, speed)
    assert abs(c.alt - nearest.alt) <= 3000 and abs(c.relative_alt - nearest.relative_alt) <= 3000
    path = ftp / "DCIM" / "100GCSD" / f"IMG_{c.image_index:05d}.JPG"
    lat, lon, alt = read_position(path.read_bytes())
    assert distance_m(lat, lon, c.lat / 1e7, c.lon / 1e7) < 0.05  # the same instant, to the centimetre
    assert abs(alt - c.alt / 1000) < 0.01


def test_mission_trigger_distance_leaves_photos_along_the_route(camera):
    gcs, ftp = camera
    end = offset(*HOME[:2], 100.0, 0.0)  # 100 m north
    start_e7, end_e7 = (round(HOME[0] * 1e7), round(HOME[1] * 1e7)), (round(end[0] * 1e7), round(end[1] * 1e7))
    # a DO item runs while the NAV item before it is flown (AP_Mission): the trigger is set on the way
    # to the start of the line and cleared on the way from its end
    items = [
        MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 0, 1, 0, 0, 0, 0, *start_e7, HOME[2]),
        MissionItem(M.MAV_CMD_NAV_TAKEOFF, REL, 0, 1, 0, 0, 0, 0, 0, 0, 20.0),
        MissionItem(M.MAV_CMD_NAV_WAYPOINT, REL, 0, 1, 0, 0, 0, 0, *start_e7, 20.0),
        MissionItem(M.MAV_CMD_DO_SET_CAM_TRIGG_DIST, M.MAV_FRAME_MISSION, 0, 1, 20.0, 0, 0, 0, 0, 0, 0),
        MissionItem(M.MAV_CMD_NAV_WAYPOINT, REL, 0, 1, 0, 0, 0, 0, *end_e7, 20.0),
        MissionItem(M.MAV_CMD_NAV_LAND, REL, 0, 1, 0, 0, 0, 0, *end_e7, 0),
        MissionItem(M.MAV_CMD_DO_SET_CAM_TRIGG_DIST, M.MAV_FRAME_MISSION, 0, 1, 0, 0, 0, 0, 0, 0, 0),
    ]
    assert MissionClient(gcs).upload(items) == M.MAV_MISSION_ACCEPTED
    assert command(gcs, M.MAV_CMD_DO_SET_MODE, 1, 4) == M.MAV_RESULT_ACCEPTED  # GUIDED, to arm
    assert command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_MISSION_START, 0, 0) == M.MAV_RESULT_ACCEPTED  # AUTO, from the first item
    reached = wait_for(gcs, lambda r: r.type == "MISSION_ITEM_REACHED" and r.msg.seq == 4, 60.0)
    assert reached is not None, "the mission never reached its waypoint"
    photos = sorted((ftp / "DCIM" / "100GCSD").glob("IMG_*.JPG"))
    spots = [read_position(p.read_bytes()) for p in photos]
    assert len(spots) >= 4, f"{len(spots)} photos over 100 m at 20 m"
    for lat, lon, alt in spots:  # every photo on the route: on the line north, at mission altitude
        north = distance_m(HOME[0], HOME[1], lat, HOME[1]) * (1 if lat > HOME[0] else -1)
        assert -1 <= north <= 101 and distance_m(lat, HOME[1], lat, lon) < 3, (lat, lon)
        assert abs(alt - (HOME[2] + 20)) < 2, alt
    steps = [distance_m(a[0], a[1], b[0], b[1]) for a, b in itertools.pairwise(spots)]
    # every 20 m (a late send pass adds what the vehicle flew meanwhile)
    assert all(19 <= s <= 30 for s in steps), steps


def test_camera_commands_answer_from_the_right_component(camera):
    gcs, ftp = camera
    # the autopilot's AP_Camera answers: zoom CONTINUOUS / RANGE only, STEP is UNSUPPORTED there
    assert command(gcs, M.MAV_CMD_SET_CAMERA_ZOOM, M.ZOOM_TYPE_STEP, 1) == M.MAV_RESULT_UNSUPPORTED
    assert command(gcs, M.MAV_CMD_SET_CAMERA_ZOOM, M.ZOOM_TYPE_STEP, 1, target=CAMERA) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_SET_CAMERA_ZOOM, M.ZOOM_TYPE_RANGE, 50) == M.MAV_RESULT_ACCEPTED
    settings = requested(gcs, M.MAV_CMD_REQUEST_MESSAGE, "CAMERA_SETTINGS", M.MAVLINK_MSG_ID_CAMERA_SETTINGS)
    assert settings.zoomLevel == 50
    assert command(gcs, M.MAV_CMD_SET_CAMERA_FOCUS, M.FOCUS_TYPE_METERS, 5, target=CAMERA) == M.MAV_RESULT_DENIED
    assert command(gcs, M.MAV_CMD_SET_CAMERA_FOCUS, M.FOCUS_TYPE_RANGE, 40, target=CAMERA) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_SET_CAMERA_MODE, 0, M.CAMERA_MODE_VIDEO, target=CAMERA) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_VIDEO_START_CAPTURE, 0, 0, target=CAMERA) == M.MAV_RESULT_ACCEPTED
    status = requested(gcs, M.MAV_CMD_REQUEST_MESSAGE, "CAMERA_CAPTURE_STATUS", M.MAVLINK_MSG_ID_CAMERA_CAPTURE_STATUS)
    assert status.video_status == 1
    assert command(gcs, M.MAV_CMD_SET_CAMERA_MODE, 0, M.CAMERA_MODE_IMAGE, target=CAMERA) == M.MAV_RESULT_DENIED
    assert command(gcs, M.MAV_CMD_VIDEO_STOP_CAPTURE, 0, target=CAMERA) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_IMAGE_START_CAPTURE, -1, 0, 1, target=CAMERA) == M.MAV_RESULT_UNSUPPORTED
    assert command(gcs, M.MAV_CMD_IMAGE_START_CAPTURE, 0, math.nan, 1, target=CAMERA) == M.MAV_RESULT_DENIED
    # DO_DIGICAM_CONTROL p5 = 1 at the autopilot shoots with the camera; STORAGE_FORMAT at the camera empties it
    mark = gcs.mark()
    assert command(gcs, M.MAV_CMD_DO_DIGICAM_CONTROL, 0, 0, 0, 0, 1, 0, 0) == M.MAV_RESULT_ACCEPTED
    assert wait_for(gcs, lambda r: r.type == "CAMERA_IMAGE_CAPTURED", since=mark)
    assert list((ftp / "DCIM" / "100GCSD").glob("*.JPG"))
    assert command(gcs, M.MAV_CMD_STORAGE_FORMAT, 1, 1, target=CAMERA) == M.MAV_RESULT_ACCEPTED
    assert not list((ftp / "DCIM" / "100GCSD").glob("*.JPG"))
    storage = requested(gcs, M.MAV_CMD_REQUEST_MESSAGE, "STORAGE_INFORMATION", M.MAVLINK_MSG_ID_STORAGE_INFORMATION)
    assert storage.used_capacity == 0
    # what the camera does not know: UNSUPPORTED, from the camera
    assert command(gcs, M.MAV_CMD_DO_SET_MODE, 1, 4, target=CAMERA) == M.MAV_RESULT_UNSUPPORTED


def test_without_the_camera_nothing_answers_from_compid_100(daemon, client):
    d = daemon({"channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]})
    gcs = client(f"udpout:127.0.0.1:{d.port('gcs')}", *QGC)
    gcs.heartbeat()
    assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == AUTOPILOT)
    mark = gcs.mark()
    assert command(gcs, M.MAV_CMD_IMAGE_START_CAPTURE, 0, 0, 1) == M.MAV_RESULT_FAILED  # AP_Camera: no instance
    from .helpers import pump_until
    # a camera heartbeats every second: in this window (1.5 s, and on until the autopilot's
    # HEARTBEAT, the control, has come however late) the autopilot's did, the camera's not
    assert pump_until([gcs], lambda: [r for r in gcs.since(mark) if r.type == "HEARTBEAT" and r.src == AUTOPILOT],
                      at_least_s=1.5), "no HEARTBEAT from the autopilot"
    assert not [r for r in gcs.since(mark) if r.src == CAMERA]


def test_gcsd_status_counts_the_photos(daemon, client):
    d = daemon({"vehicle": {"camera": True},
                "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]})
    gcs = client(f"udpout:127.0.0.1:{d.port('gcs')}", *QGC)
    gcs.heartbeat()
    assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == CAMERA)
    assert d.status()["counters"]["camera_photos"] == 0
    for n in (1, 2):
        mark = gcs.mark()
        assert command(gcs, M.MAV_CMD_IMAGE_START_CAPTURE, 0, 0, 1, target=CAMERA) == M.MAV_RESULT_ACCEPTED
        assert wait_for(gcs, lambda r, n=n: r.type == "CAMERA_IMAGE_CAPTURED" and r.msg.image_index == n, since=mark)
    counters = d.status()["counters"]
    assert (counters["camera_photos"], counters["camera_photo_failures"]) == (2, 0)


def test_a_swarm_has_one_camera_per_vehicle(daemon, client, tmp_path):
    d = daemon({"vehicle": {"camera": True, "count": 2},
                "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]})
    gcs = client(f"udpout:127.0.0.1:{d.port('gcs')}", *QGC)
    gcs.heartbeat()
    for sysid in (1, 2):
        hb = wait_for(gcs, lambda r, s=sysid: r.type == "HEARTBEAT" and r.src == (s, 100))
        assert hb is not None and hb.msg.type == M.MAV_TYPE_CAMERA
    mark = gcs.mark()
    assert command(gcs, M.MAV_CMD_IMAGE_START_CAPTURE, 0, 0, 1, target=(2, 100)) == M.MAV_RESULT_ACCEPTED
    captured = wait_for(gcs, lambda r: r.type == "CAMERA_IMAGE_CAPTURED", since=mark)
    assert captured is not None and captured.src == (2, 100)
    assert (tmp_path / "state" / "vehicle-2" / "ftp" / "DCIM" / "100GCSD" / "IMG_00001.JPG").is_file()
    assert not (tmp_path / "state" / "vehicle-1" / "ftp" / "DCIM" / "100GCSD" / "IMG_00001.JPG").exists()
