"""The camera core (gcsd.payloads.camera) with a fake clock: AP_Camera's answers, single, interval, count
and distance-triggered photos with the pose of their instant, zoom, focus, storage; the JPEG's
EXIF position is the photo's."""

from __future__ import annotations

import itertools

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.payloads.camera import messages
from gcsd.payloads.camera.camera import IMAGE, MIN_INTERVAL_S, VIDEO, Camera, CameraPose
from gcsd.payloads.camera.jpeg import encode, read_position
from gcsd.vehicle.sim.geo import offset

ACCEPTED, DENIED, UNSUPPORTED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_DENIED, M.MAV_RESULT_UNSUPPORTED
HOME = (-35.363262, 149.165237)


def pose(north_m: float = 0.0, alt: float = 634.0) -> CameraPose:
    lat, lon = offset(*HOME, north_m, 0.0)
    return CameraPose(lat, lon, alt, alt - 584.0, 0.0, 0.0, 0.5)


def run(cam: Camera, start: float, seconds: float, dt: float = 0.05, moving_ms: float = 0.0) -> list:
    shots, t = [], start
    while t < start + seconds - 1e-9:
        t += dt
        shots += cam.step(t, pose(north_m=moving_ms * t))
    return shots


def test_single_photo_is_taken_at_the_next_step_with_that_instants_pose():
    cam = Camera(0.0)
    assert cam.image_start(0, 0, 1) == ACCEPTED
    assert cam.image_status() == 1
    shots = cam.step(1.0, pose(north_m=5.0))
    assert [s.index for s in shots] == [1] and shots[0].pose == pose(north_m=5.0) and shots[0].now == 1.0
    assert shots[0].filename == "IMG_00001.JPG"
    assert cam.step(2.0, pose()) == [] and cam.image_status() == 0


def test_zero_interval_and_count_is_one_photo_and_a_negative_camera_is_unsupported():
    cam = Camera(0.0)
    assert cam.image_start(0, 0, 0) == ACCEPTED
    assert len(cam.step(0.1, pose())) == 1
    assert cam.image_start(-1, 0, 1) == UNSUPPORTED
    assert cam.image_stop(-1) == UNSUPPORTED


def test_interval_with_count_takes_that_many_then_stops():
    cam = Camera(0.0)
    assert cam.image_start(0, 1.0, 3) == ACCEPTED
    assert cam.image_status() == 3 and cam.next_deadline() == 0.0
    shots = run(cam, 0.0, 10.0)
    assert [round(s.now, 2) for s in shots] == [0.05, 1.05, 2.05]
    assert cam.image_status() == 0 and cam.next_deadline() is None


def test_interval_forever_until_stopped():
    cam = Camera(0.0)
    cam.image_start(0, 2.0, 0)
    assert len(run(cam, 0.0, 9.0)) == 5
    assert cam.image_stop(0) == ACCEPTED
    assert run(cam, 9.0, 10.0) == []


def test_photos_are_at_least_the_minimum_interval_apart():
    cam = Camera(0.0)
    for _ in range(3):
        cam.image_start(0, 0, 1)
    shots = run(cam, 0.0, 1.0, dt=0.01)
    assert len(shots) == 3
    assert all(b.now - a.now >= MIN_INTERVAL_S - 1e-9 for a, b in itertools.pairwise(shots))


def test_trigger_distance_takes_a_photo_every_so_many_metres():
    cam = Camera(0.0)
    assert cam.set_trigger_distance(20.0, 0) == ACCEPTED
    shots = run(cam, 0.0, 10.0, dt=0.1, moving_ms=10.0)  # 100 m north at 10 m/s
    assert len(shots) == 4  # the first position is remembered, then every 20 m
    norths = [(s.pose.lat - HOME[0]) * 111319.49 for s in shots]
    assert all(b - a == pytest.approx(20.0, abs=1.1) for a, b in itertools.pairwise(norths))
    cam.set_trigger_distance(0.0, 1)  # off, with one photo now
    assert len(run(cam, 10.0, 5.0, dt=0.1, moving_ms=10.0)) == 1


def test_digicam_control_shoots_only_with_p5_one():
    cam = Camera(0.0)
    assert cam.digicam_control(0) == ACCEPTED and cam.step(1.0, pose()) == []
    assert cam.digicam_control(1) == ACCEPTED and len(cam.step(2.0, pose())) == 1


def test_video_mode_refuses_a_sequence_and_mode_change_while_busy():
    cam = Camera(0.0)
    assert cam.set_mode(VIDEO) == ACCEPTED
    assert cam.image_start(0, 1.0, 0) == DENIED
    assert cam.image_start(0, 0, 1) == ACCEPTED  # a still while in video mode: the camera can
    assert cam.video(True, 5.0) == ACCEPTED and cam.recording_ms(7.5) == 2500
    assert cam.set_mode(IMAGE) == DENIED
    assert cam.video(False, 8.0) == ACCEPTED and cam.recording_ms(9.0) == 0
    assert cam.set_mode(IMAGE) == ACCEPTED
    assert cam.set_mode(2) == DENIED  # survey: not this camera


def test_zoom_range_continuous_step_and_focus():
    cam = Camera(0.0)
    assert cam.set_zoom(M.ZOOM_TYPE_RANGE, 50) == ACCEPTED and cam.focal_length_mm == pytest.approx(24.75)
    assert cam.set_zoom(M.ZOOM_TYPE_CONTINUOUS, 1) == ACCEPTED
    cam.step(1.0, pose())
    assert cam.zoom_pct == pytest.approx(70.0)
    cam.set_zoom(M.ZOOM_TYPE_CONTINUOUS, 0)
    cam.step(2.0, pose())
    assert cam.zoom_pct == pytest.approx(70.0)
    assert cam.set_zoom(M.ZOOM_TYPE_STEP, -1) == ACCEPTED and cam.zoom_pct == pytest.approx(60.0)
    assert cam.set_zoom(M.ZOOM_TYPE_RANGE, 150) == UNSUPPORTED
    assert cam.set_focus(M.FOCUS_TYPE_RANGE, 30) == ACCEPTED and cam.focus_pct == 30
    assert cam.set_focus(M.FOCUS_TYPE_AUTO, 0) == ACCEPTED and cam.focus_pct == 100
    assert cam.set_focus(M.FOCUS_TYPE_METERS, 5) == DENIED


def test_storage_counts_what_was_written_and_format_empties_it():
    cam = Camera(0.0)
    full = cam.available_mib()
    cam.stored(2 * 1048576)
    assert cam.available_mib() == pytest.approx(full - 2)
    info = messages.storage_information(0, cam)
    assert info.used_capacity == pytest.approx(2.0) and info.status == M.STORAGE_STATUS_READY
    assert cam.format_storage() == ACCEPTED and cam.available_mib() == full


def test_messages_describe_the_camera_and_each_photo():
    cam = Camera(0.0)
    info = messages.information(10, 1)
    assert info.flags & M.CAMERA_CAP_FLAGS_CAPTURE_IMAGE and info.gimbal_device_id == 1
    assert (info.resolution_h, info.resolution_v) == messages.RESOLUTION
    cam.image_start(0, 0, 1)
    shot = cam.step(1.0, pose(north_m=10.0))[0]
    captured = messages.image_captured(shot, 1000, 1_700_000_000_000_000, "mftp://x", True)
    assert (captured.lat, captured.lon) == (round(shot.pose.lat * 1e7), round(shot.pose.lon * 1e7))
    assert captured.alt == 634000 and captured.relative_alt == 50000 and captured.capture_result == 1
    feedback = messages.camera_feedback(shot, 1_000_000, 1)
    assert (feedback.lat, feedback.lng, feedback.img_idx) == (captured.lat, captured.lon, 1)
    assert feedback.flags == M.CAMERA_FEEDBACK_PHOTO
    assert messages.capture_status(0, cam, 1.0).image_count == 1
    mav = M.MAVLink(None, 1, 100)
    for msg in (info, messages.settings(0, cam), messages.capture_status(0, cam, 1.0),
                messages.storage_information(0, cam), messages.video_stream_information(cam), captured, feedback):
        decoded = M.MAVLink(None).decode(bytearray(msg.pack(mav)))  # every message packs and decodes
        assert decoded.get_type() == msg.get_type()


def test_jpeg_exif_holds_the_photos_position():
    cam = Camera(0.0)
    cam.image_start(0, 0, 1)
    shot = cam.step(1.0, pose(north_m=123.4, alt=700.5))[0]
    data = encode(shot, 1_764_000_000.0, cam.focal_length_mm)
    assert data[:2] == b"\xff\xd8" and data[-2:] == b"\xff\xd9"
    lat, lon, alt = read_position(data)
    assert (lat, lon, alt) == pytest.approx((shot.pose.lat, shot.pose.lon, 700.5), abs=1e-7)
