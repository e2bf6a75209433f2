"""What the simulated camera says (camera protocol v2), built from the core's state. Pure.

CAMERA_INFORMATION: vendor "gcsd", model "SimCam", a 640x480 sensor of 6.17 x 4.55 mm, a 4.5-45 mm
zoom; it captures images and video, has modes, basic zoom and focus, takes photos while recording
and records while in image mode; no definition file (a basic camera: QGroundControl asks for no
parameters). `gimbal_device_id` names the gimbal it sits on (1 with `vehicle.gimbal`, else 0).
CAMERA_IMAGE_CAPTURED (from the camera) and CAMERA_FEEDBACK (from the autopilot, as AP_Camera)
carry the position and attitude of the photo's instant, the same numbers as the JPEG's EXIF.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.payloads.camera.camera import FOCAL_LENGTH_MM, STORAGE_TOTAL_MIB, Camera, Shot
from gcsd.payloads.gimbal.geometry import quaternion

VENDOR, MODEL = b"gcsd", b"SimCam"
FIRMWARE_VERSION = 1 | (0 << 8) | (0 << 16)
SENSOR_MM = (6.17, 4.55)
RESOLUTION = (640, 480)
CAPABILITIES = (M.CAMERA_CAP_FLAGS_CAPTURE_IMAGE | M.CAMERA_CAP_FLAGS_CAPTURE_VIDEO | M.CAMERA_CAP_FLAGS_HAS_MODES
                | M.CAMERA_CAP_FLAGS_CAN_CAPTURE_IMAGE_IN_VIDEO_MODE
                | M.CAMERA_CAP_FLAGS_CAN_CAPTURE_VIDEO_IN_IMAGE_MODE
                | M.CAMERA_CAP_FLAGS_HAS_BASIC_ZOOM | M.CAMERA_CAP_FLAGS_HAS_BASIC_FOCUS)


def _e7(deg: float) -> int:
    return round(deg * 1e7)


def information(time_ms: int, gimbal_device_id: int):
    return M.MAVLink_camera_information_message(
        time_ms, list(VENDOR.ljust(32, b"\0")), list(MODEL.ljust(32, b"\0")), FIRMWARE_VERSION,
        FOCAL_LENGTH_MM[0], SENSOR_MM[0], SENSOR_MM[1], *RESOLUTION, 0,
        CAPABILITIES, 0, b"", gimbal_device_id, 0)


def settings(time_ms: int, cam: Camera):
    return M.MAVLink_camera_settings_message(time_ms, cam.mode, cam.zoom_pct, cam.focus_pct, 0)


def capture_status(time_ms: int, cam: Camera, now: float):
    video = 1 if cam.recording_since_s is not None else 0
    return M.MAVLink_camera_capture_status_message(
        time_ms, cam.image_status(), video, cam.interval_s if cam.remaining else 0.0, cam.recording_ms(now),
        cam.available_mib(), cam.captured, 0)


def storage_information(time_ms: int, cam: Camera):
    used = cam.used_bytes / 1048576.0
    return M.MAVLink_storage_information_message(
        time_ms, 1, 1, M.STORAGE_STATUS_READY, STORAGE_TOTAL_MIB, used, cam.available_mib(), 90.0, 60.0,
        M.STORAGE_TYPE_SD, b"SimCam SD", M.STORAGE_USAGE_FLAG_SET | M.STORAGE_USAGE_FLAG_PHOTO
        | M.STORAGE_USAGE_FLAG_VIDEO)


def video_stream_information(cam: Camera):
    """One stream, described; gcsd serves no video itself (status not running, no URI)."""
    return M.MAVLink_video_stream_information_message(
        1, 1, M.VIDEO_STREAM_TYPE_RTSP, 0, 30.0, *RESOLUTION, 2000, 0, 63, b"SimCam", b"",
        M.VIDEO_STREAM_ENCODING_H264, 0)


def image_captured(shot: Shot, time_ms: int, time_utc_us: int, file_url: str, ok: bool):
    p = shot.pose
    return M.MAVLink_camera_image_captured_message(
        time_ms, time_utc_us, 0, _e7(p.lat), _e7(p.lon), round(p.alt_amsl_m * 1000), round(p.relative_alt_m * 1000),
        quaternion(p.roll_rad, p.pitch_rad, p.yaw_rad), shot.index, 1 if ok else 0, file_url.encode())


def camera_feedback(shot: Shot, time_usec: int, completed: int):
    p = shot.pose
    return M.MAVLink_camera_feedback_message(
        time_usec, 0, 0, shot.index, _e7(p.lat), _e7(p.lon), p.alt_amsl_m, p.relative_alt_m,
        math.degrees(p.roll_rad), math.degrees(p.pitch_rad), math.degrees(p.yaw_rad), 0.0,
        M.CAMERA_FEEDBACK_PHOTO, completed)
