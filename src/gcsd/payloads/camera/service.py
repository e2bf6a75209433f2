"""The simulated camera: a MAVLink component of its own (compid 100), and the autopilot's camera.

The component: HEARTBEAT every second on every link (MAV_TYPE_CAMERA, MAV_AUTOPILOT_INVALID,
as QGroundControl's camera manager and MAVSDK's camera plugin expect), its own command table
(`CAMERA_COMMANDS`; ACKs come from compid 100): REQUEST_MESSAGE for CAMERA_INFORMATION,
CAMERA_SETTINGS, CAMERA_CAPTURE_STATUS, STORAGE_INFORMATION, VIDEO_STREAM_INFORMATION and the
legacy REQUEST_CAMERA_INFORMATION / _SETTINGS / _CAPTURE_STATUS, REQUEST_STORAGE_INFORMATION,
REQUEST_VIDEO_STREAM_INFORMATION (ACCEPTED, then the message on the asking link, after the ACK);
IMAGE_START/STOP_CAPTURE, VIDEO_START/STOP_CAPTURE, SET_CAMERA_MODE, SET_CAMERA_ZOOM,
SET_CAMERA_FOCUS, STORAGE_FORMAT (the photos are deleted), RESET_CAMERA_SETTINGS, and the
autopilot-style DO_DIGICAM_CONTROL / DO_SET_CAM_TRIGG_DIST.

The autopilot (compid 1) takes the camera commands AP_Camera takes (DO_DIGICAM_CONTROL,
DO_SET_CAM_TRIGG_DIST, IMAGE_START/STOP_CAPTURE, VIDEO_START/STOP_CAPTURE, SET_CAMERA_ZOOM
(CONTINUOUS and RANGE only, else UNSUPPORTED), SET_CAMERA_FOCUS) and runs the mission's camera
items (DO_DIGICAM_CONTROL, DO_SET_CAM_TRIGG_DIST, IMAGE_START/STOP_CAPTURE, VIDEO_START/STOP)
on the same camera.

Each photo (taken at a send pass, with the vehicle's position and the camera's attitude at that
instant: the gimbal's when there is one) is written as `DCIM/100GCSD/IMG_nnnnn.JPG` under the FTP
root (a real JPEG with EXIF GPS; numbering goes on after the files already there), then
CAMERA_IMAGE_CAPTURED (from the camera, with an mftp:// URL to the file) and CAMERA_FEEDBACK (from
the autopilot) go to every link. A photo that cannot be written is reported with capture_result 0
and counted. Outboxes are bounded (OUTBOX_MAX per link; the oldest are dropped and counted).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.payloads.camera import jpeg, messages
from gcsd.payloads.camera.camera import ACCEPTED, IMAGE, UNSUPPORTED, Camera, CameraPose, Shot
from gcsd.vehicle.services import Service
from gcsd.vehicle.services.commands import CommandRequest

log = structlog.get_logger("gcsd.payloads.camera")

CAMERA_COMPID = M.MAV_COMP_ID_CAMERA  # 100
HEARTBEAT_INTERVAL_S = 1.0
MIN_PASS_S = 0.01  # a photo deadline is never in the past (no spinning send pass)
OUTBOX_MAX = 64
PHOTO_DIR = Path("DCIM") / "100GCSD"
PHOTO_NAME = re.compile(r"IMG_(\d{5})\.JPG")
REQUESTABLE = {
    M.MAVLINK_MSG_ID_CAMERA_INFORMATION, M.MAVLINK_MSG_ID_CAMERA_SETTINGS, M.MAVLINK_MSG_ID_CAMERA_CAPTURE_STATUS,
    M.MAVLINK_MSG_ID_STORAGE_INFORMATION, M.MAVLINK_MSG_ID_VIDEO_STREAM_INFORMATION,
}
LEGACY_REQUESTS = {
    M.MAV_CMD_REQUEST_CAMERA_INFORMATION: M.MAVLINK_MSG_ID_CAMERA_INFORMATION,
    M.MAV_CMD_REQUEST_CAMERA_SETTINGS: M.MAVLINK_MSG_ID_CAMERA_SETTINGS,
    M.MAV_CMD_REQUEST_CAMERA_CAPTURE_STATUS: M.MAVLINK_MSG_ID_CAMERA_CAPTURE_STATUS,
    M.MAV_CMD_REQUEST_STORAGE_INFORMATION: M.MAVLINK_MSG_ID_STORAGE_INFORMATION,
    M.MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION: M.MAVLINK_MSG_ID_VIDEO_STREAM_INFORMATION,
}


def _existing_photos(directory: Path) -> tuple[int, int]:
    """(the highest photo number, the bytes they take) of the photos already in `directory`."""
    highest, size = 0, 0
    try:
        for entry in directory.iterdir():
            match = PHOTO_NAME.fullmatch(entry.name)
            if match and entry.is_file():
                highest = max(highest, int(match.group(1)))
                size += entry.stat().st_size
    except OSError:
        pass
    return highest, size


class CameraService(Service):
    def __init__(self, ctx, ftp_root: Path | None, now: float, gimbal=None) -> None:
        self.ctx = ctx
        self.gimbal = gimbal  # the gimbal service the camera sits on, if any (its attitude, its device id)
        self.photo_dir = None if ftp_root is None else Path(ftp_root) / PHOTO_DIR
        highest, size = _existing_photos(self.photo_dir) if self.photo_dir is not None else (0, 0)
        self.camera = Camera(now, first_index=highest + 1)
        self.camera.stored(size)
        self.outbox: dict[int, list[tuple[object, int]]] = {}  # channel index -> (message, from compid)
        self._heartbeat_due: dict[int, float] = {}
        self.photos_written = 0
        self.photo_failures = 0
        self.outbox_dropped = 0

    def counters(self) -> dict[str, int]:
        return {"camera_photos": self.photos_written, "camera_photo_failures": self.photo_failures,
                "camera_outbox_dropped": self.outbox_dropped}

    # --- tables --------------------------------------------------------------------------------
    def local_components(self) -> dict:
        """The camera component: commands addressed to compid 100 run from its own table."""
        return {CAMERA_COMPID: self.camera_commands()}

    def camera_commands(self) -> dict:
        """The camera component's own command table (compid 100)."""
        c = self.camera
        table = {
            M.MAV_CMD_REQUEST_MESSAGE: self.request_message,
            M.MAV_CMD_IMAGE_START_CAPTURE: self.image_start, M.MAV_CMD_IMAGE_STOP_CAPTURE: self.image_stop,
            M.MAV_CMD_VIDEO_START_CAPTURE: self.video_start, M.MAV_CMD_VIDEO_STOP_CAPTURE: self.video_stop,
            M.MAV_CMD_SET_CAMERA_MODE: lambda req: self._changed(req, c.set_mode(req.param2)),
            M.MAV_CMD_SET_CAMERA_ZOOM: lambda req: self._changed(req, c.set_zoom(req.param1, req.param2)),
            M.MAV_CMD_SET_CAMERA_FOCUS: lambda req: self._changed(req, c.set_focus(req.param1, req.param2)),
            M.MAV_CMD_STORAGE_FORMAT: self.storage_format,
            M.MAV_CMD_RESET_CAMERA_SETTINGS: self.reset_settings,
            M.MAV_CMD_DO_DIGICAM_CONTROL: self.digicam_control,
            M.MAV_CMD_DO_SET_CAM_TRIGG_DIST: self.trigger_distance,
        }
        table.update({cmd: self.legacy_request for cmd in LEGACY_REQUESTS})
        return table

    def commands(self) -> dict:
        """The autopilot's camera commands (AP_Camera's), on the same camera."""
        c = self.camera
        return {
            M.MAV_CMD_DO_DIGICAM_CONTROL: self.digicam_control, M.MAV_CMD_DO_SET_CAM_TRIGG_DIST: self.trigger_distance,
            M.MAV_CMD_IMAGE_START_CAPTURE: self.image_start, M.MAV_CMD_IMAGE_STOP_CAPTURE: self.image_stop,
            M.MAV_CMD_VIDEO_START_CAPTURE: self.video_start, M.MAV_CMD_VIDEO_STOP_CAPTURE: self.video_stop,
            M.MAV_CMD_SET_CAMERA_ZOOM: self.autopilot_zoom,
            M.MAV_CMD_SET_CAMERA_FOCUS: lambda req: self._changed(req, c.set_focus(req.param1, req.param2)),
        }

    def mission_items(self) -> dict:
        """Mission DO items the autopilot hands to the camera (Autopilot.payload_items)."""
        c = self.camera
        now = self.ctx.now
        return {
            M.MAV_CMD_DO_DIGICAM_CONTROL: lambda item: c.digicam_control(item.x),
            M.MAV_CMD_DO_SET_CAM_TRIGG_DIST: lambda item: c.set_trigger_distance(item.param1, item.param3),
            M.MAV_CMD_IMAGE_START_CAPTURE: lambda item: c.image_start(item.param1, item.param2, item.param3),
            M.MAV_CMD_IMAGE_STOP_CAPTURE: lambda item: c.image_stop(item.param1),
            M.MAV_CMD_VIDEO_START_CAPTURE: lambda item: c.video(True, now()),
            M.MAV_CMD_VIDEO_STOP_CAPTURE: lambda item: c.video(False, now()),
        }

    # --- commands ------------------------------------------------------------------------------
    def _changed(self, req: CommandRequest, result: int) -> int:
        self.ctx.wake(req.inc.channel)  # a photo or a status may be due at once
        return result

    def image_start(self, req: CommandRequest) -> int:
        return self._changed(req, self.camera.image_start(req.param1, req.param2, req.param3))

    def image_stop(self, req: CommandRequest) -> int:
        return self.camera.image_stop(req.param1)

    def video_start(self, req: CommandRequest) -> int:
        return self.camera.video(True, req.inc.now)

    def video_stop(self, req: CommandRequest) -> int:
        return self.camera.video(False, req.inc.now)

    def digicam_control(self, req: CommandRequest) -> int:
        return self._changed(req, self.camera.digicam_control(req.x))

    def trigger_distance(self, req: CommandRequest) -> int:
        return self._changed(req, self.camera.set_trigger_distance(req.param1, req.param3))

    def autopilot_zoom(self, req: CommandRequest) -> int:
        if req.param1 not in (M.ZOOM_TYPE_CONTINUOUS, M.ZOOM_TYPE_RANGE):
            return UNSUPPORTED
        return self.camera.set_zoom(req.param1, req.param2)

    def reset_settings(self, req: CommandRequest) -> int:
        c = self.camera
        if c.recording_since_s is not None or c.remaining:
            return M.MAV_RESULT_DENIED
        c.mode, c.zoom_pct, c.zoom_rate, c.focus_pct, c.focus_rate = IMAGE, 0.0, 0.0, 0.0, 0.0
        return ACCEPTED

    def storage_format(self, req: CommandRequest) -> int:
        if self.photo_dir is not None:
            try:
                for entry in self.photo_dir.iterdir():
                    if PHOTO_NAME.fullmatch(entry.name):
                        entry.unlink()
            except FileNotFoundError:
                pass
            except OSError as exc:
                log.error("camera_format_failed", error=str(exc))
                return M.MAV_RESULT_FAILED
        return self.camera.format_storage()

    def request_message(self, req: CommandRequest) -> int:
        msgid = int(req.param1)
        if msgid not in REQUESTABLE:
            return M.MAV_RESULT_DENIED
        self._queue(req.inc.channel.index, self._message(msgid, req.inc.now), CAMERA_COMPID)
        self.ctx.wake(req.inc.channel)
        return ACCEPTED

    def legacy_request(self, req: CommandRequest) -> int:
        self._queue(req.inc.channel.index, self._message(LEGACY_REQUESTS[req.command], req.inc.now), CAMERA_COMPID)
        self.ctx.wake(req.inc.channel)
        return ACCEPTED

    def _message(self, msgid: int, now: float):
        time_ms = self.ctx.time_boot_ms(now)
        c = self.camera
        if msgid == M.MAVLINK_MSG_ID_CAMERA_INFORMATION:
            return messages.information(time_ms, 1 if self.gimbal is not None else 0)
        if msgid == M.MAVLINK_MSG_ID_CAMERA_SETTINGS:
            return messages.settings(time_ms, c)
        if msgid == M.MAVLINK_MSG_ID_CAMERA_CAPTURE_STATUS:
            return messages.capture_status(time_ms, c, now)
        if msgid == M.MAVLINK_MSG_ID_STORAGE_INFORMATION:
            return messages.storage_information(time_ms, c)
        return messages.video_stream_information(c)

    # --- photos ----------------------------------------------------------------------------------
    def pose(self) -> CameraPose:
        s = self.ctx.state
        roll, pitch, yaw = s.roll_rad, s.pitch_rad, s.yaw_rad
        if self.gimbal is not None:  # the camera sits on the gimbal: earth-frame roll and pitch, yaw on the body
            g_roll, g_pitch, g_yaw = self.gimbal.mount.attitude
            roll, pitch, yaw = g_roll, g_pitch, (yaw + g_yaw) % (2 * math.pi)
        return CameraPose(s.lat, s.lon, s.alt_amsl_m, s.relative_alt_m, roll, pitch, yaw)

    def _take(self, shot: Shot, now: float) -> None:
        ok = False
        url = ""
        if self.photo_dir is not None:
            data = jpeg.encode(shot, self.ctx.wall(), self.camera.focal_length_mm)
            try:
                self.photo_dir.mkdir(parents=True, exist_ok=True)
                (self.photo_dir / shot.filename).write_bytes(data)
                self.camera.stored(len(data))
                ok = True
                url = f"mftp://[;comp={self.ctx.compid}]/{(PHOTO_DIR / shot.filename).as_posix()}"
            except OSError as exc:
                log.error("camera_photo_failed", file=shot.filename, error=str(exc))
        if ok:
            self.photos_written += 1
        else:
            self.photo_failures += 1
        time_ms = self.ctx.time_boot_ms(shot.now)
        captured = messages.image_captured(shot, time_ms, int(self.ctx.wall() * 1e6), url, ok)
        feedback = messages.camera_feedback(shot, self.ctx.time_usec(shot.now), self.photos_written)
        for channel in self.ctx.channels:
            self._queue(channel.index, captured, CAMERA_COMPID)
            self._queue(channel.index, feedback, self.ctx.compid)
            self.ctx.wake(channel)

    def _queue(self, index: int, msg, compid: int) -> None:
        box = self.outbox.setdefault(index, [])
        box.append((msg, compid))
        if len(box) > OUTBOX_MAX:
            del box[0]
            self.outbox_dropped += 1

    def pending(self, channel, now: float, send) -> float | None:
        for shot in self.camera.step(now, self.pose()):
            self._take(shot, now)
        sysid = self.ctx.sysid
        due = self._heartbeat_due.get(channel.index, 0.0)
        if now >= due:
            channel.send_message(M.MAVLink_heartbeat_message(
                M.MAV_TYPE_CAMERA, M.MAV_AUTOPILOT_INVALID, 0, 0, M.MAV_STATE_ACTIVE, 3), sysid, CAMERA_COMPID)
            due = now + HEARTBEAT_INTERVAL_S
            self._heartbeat_due[channel.index] = due
        for msg, compid in self.outbox.pop(channel.index, []):
            channel.send_message(msg, sysid, compid)
        photo_due = self.camera.next_deadline()
        return due if photo_due is None else min(due, max(photo_due, now + MIN_PASS_S))
