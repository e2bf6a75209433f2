"""The camera core: what a MAVLink camera does with its commands and the vehicle's motion. Pure.

States: mode IMAGE or VIDEO (SET_CAMERA_MODE); photo capture idle, single pending, or an interval
sequence (`interval_s`, `remaining`: -1 for ever) as AP_Camera's take_multiple_pictures; video
recording since `recording_since_s`; a trigger distance (DO_SET_CAM_TRIGG_DIST, 0 off); zoom and
focus as 0-100 % (SET_CAMERA_ZOOM / SET_CAMERA_FOCUS: RANGE sets, CONTINUOUS moves at
ZOOM_RATE_PCT_S per unit of rate until a 0 rate, STEP moves ZOOM_STEP_PCT); storage (used bytes of
STORAGE_TOTAL_MIB; STORAGE_FORMAT empties it).

Commands (AP_Camera::handle_command's answers): IMAGE_START_CAPTURE p1 camera id (< 0:
UNSUPPORTED), p2 interval s, p3 count (1, or 0 with no interval: one photo; 0: for ever; n: n
photos; a sequence in VIDEO mode is DENIED, as a camera that cannot take photos while recording);
IMAGE_STOP_CAPTURE; VIDEO_START/STOP_CAPTURE (start while recording: ACCEPTED, already so);
DO_DIGICAM_CONTROL p5 = 1 shoots; DO_SET_CAM_TRIGG_DIST p1 metres (p3 = 1: one photo now).

Time: `step(now, pose)` returns the photos due now, each with the pose of that instant: a single
photo pending, the next of an interval sequence (every `interval_s` from the previous one), or one
each time the vehicle has moved `trigger_distance_m` from the last photo (as AP_Camera: the first
position after enabling is only remembered; an interval sequence takes precedence). A photo
is taken at most every MIN_INTERVAL_S (CAM1_INTERVAL_MIN's role). `next_deadline()` says when the
next interval photo is due. No clock is read here.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.sim.geo import distance_m

ACCEPTED, DENIED, FAILED, UNSUPPORTED = (
    M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_DENIED, M.MAV_RESULT_FAILED, M.MAV_RESULT_UNSUPPORTED)
IMAGE, VIDEO = M.CAMERA_MODE_IMAGE, M.CAMERA_MODE_VIDEO
MIN_INTERVAL_S = 0.2
ZOOM_RATE_PCT_S = 20.0
ZOOM_STEP_PCT = 10.0
STORAGE_TOTAL_MIB = 32768.0
FOCAL_LENGTH_MM = (4.5, 45.0)  # zoom 0 % .. 100 %


@dataclass(frozen=True, slots=True)
class CameraPose:
    """The vehicle at an instant: degrees, metres (AMSL and above home), attitude in radians."""

    lat: float
    lon: float
    alt_amsl_m: float
    relative_alt_m: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float


@dataclass(frozen=True, slots=True)
class Shot:
    """One photo: its 1-based number, when (monotonic s) and where."""

    index: int
    now: float
    pose: CameraPose

    @property
    def filename(self) -> str:
        return f"IMG_{self.index:05d}.JPG"


def _clamp(v: float, lo: float, hi: float) -> float:
    return max(lo, min(hi, v))


class Camera:
    def __init__(self, now: float, first_index: int = 1) -> None:
        self.mode = IMAGE
        self.next_index = first_index
        self.pending = 0  # single photos asked for and not taken yet
        self.interval_s = 0.0
        self.remaining = 0  # photos left in the interval sequence, -1 for ever
        self.last_photo_s: float | None = None
        self.recording_since_s: float | None = None
        self.trigger_distance_m = 0.0
        self._last_trigger_at: tuple[float, float] | None = None
        self.zoom_pct = 0.0
        self.zoom_rate = 0.0
        self.focus_pct = 0.0
        self.focus_rate = 0.0
        self.used_bytes = 0
        self.captured = 0  # photos taken since the start (CAMERA_CAPTURE_STATUS.image_count)
        self._last_s = now

    # --- commands ------------------------------------------------------------------------------
    def image_start(self, camera_id: float, interval_s: float, count: float) -> int:
        if camera_id < 0 or interval_s < 0 or count < 0:
            return UNSUPPORTED if camera_id < 0 else DENIED
        if count == 1 or (interval_s == 0 and count == 0):
            self.pending += 1
            return ACCEPTED
        if self.mode == VIDEO:
            return DENIED
        self.interval_s = max(interval_s, MIN_INTERVAL_S)
        self.remaining = -1 if count == 0 else int(count)
        self.last_photo_s = None  # the first of the sequence is due now
        return ACCEPTED

    def image_stop(self, camera_id: float) -> int:
        if camera_id < 0:
            return UNSUPPORTED
        self.remaining = 0
        self.interval_s = 0.0
        return ACCEPTED

    def video(self, start: bool, now: float) -> int:
        if start and self.recording_since_s is None:
            self.recording_since_s = now
        elif not start:
            self.recording_since_s = None
        return ACCEPTED

    def set_mode(self, mode: float) -> int:
        if mode not in (IMAGE, VIDEO):
            return DENIED
        if mode != self.mode and (self.recording_since_s is not None or self.remaining):
            return DENIED  # busy: stop capturing first
        self.mode = int(mode)
        return ACCEPTED

    def digicam_control(self, shoot: float) -> int:
        if shoot == 1:
            self.pending += 1
        return ACCEPTED

    def set_trigger_distance(self, distance_m: float, shoot_now: float) -> int:
        self.trigger_distance_m = max(0.0, distance_m)
        if self.trigger_distance_m == 0:
            self._last_trigger_at = None  # as AP_Camera: the last position is forgotten only while off
        if shoot_now == 1:
            self.pending += 1
        return ACCEPTED

    def set_zoom(self, zoom_type: float, value: float) -> int:
        if zoom_type == M.ZOOM_TYPE_RANGE and 0 <= value <= 100:
            self.zoom_pct, self.zoom_rate = float(value), 0.0
        elif zoom_type == M.ZOOM_TYPE_CONTINUOUS:
            self.zoom_rate = _clamp(value, -1.0, 1.0)
        elif zoom_type == M.ZOOM_TYPE_STEP:
            self.zoom_pct = _clamp(self.zoom_pct + ZOOM_STEP_PCT * _clamp(value, -1.0, 1.0), 0.0, 100.0)
        elif zoom_type == M.ZOOM_TYPE_FOCAL_LENGTH and FOCAL_LENGTH_MM[0] <= value <= FOCAL_LENGTH_MM[1]:
            lo, hi = FOCAL_LENGTH_MM
            self.zoom_pct, self.zoom_rate = 100.0 * (value - lo) / (hi - lo), 0.0
        else:
            return UNSUPPORTED
        return ACCEPTED

    def set_focus(self, focus_type: float, value: float) -> int:
        if focus_type in (M.FOCUS_TYPE_AUTO, M.FOCUS_TYPE_AUTO_SINGLE, M.FOCUS_TYPE_AUTO_CONTINUOUS):
            self.focus_pct, self.focus_rate = 100.0, 0.0  # autofocus on a distant scene: infinity
        elif focus_type == M.FOCUS_TYPE_CONTINUOUS:
            self.focus_rate = _clamp(value, -1.0, 1.0)
        elif focus_type == M.FOCUS_TYPE_RANGE and 0 <= value <= 100:
            self.focus_pct, self.focus_rate = float(value), 0.0
        else:
            return DENIED
        return ACCEPTED

    def format_storage(self) -> int:
        self.used_bytes = 0
        return ACCEPTED

    def stored(self, nbytes: int) -> None:
        self.used_bytes += nbytes

    # --- time ----------------------------------------------------------------------------------
    def _may_shoot(self, now: float) -> bool:
        return self.last_photo_s is None or now - self.last_photo_s >= MIN_INTERVAL_S - 1e-9

    def _shoot(self, now: float, pose: CameraPose) -> Shot:
        shot = Shot(self.next_index, now, pose)
        self.next_index += 1
        self.captured += 1
        self.last_photo_s = now
        self._last_trigger_at = (pose.lat, pose.lon)
        return shot

    def step(self, now: float, pose: CameraPose) -> list[Shot]:
        """Zoom and focus move; the photos due now are taken (at most one per MIN_INTERVAL_S)."""
        dt = max(0.0, now - self._last_s)
        self._last_s = now
        if self.zoom_rate:
            self.zoom_pct = _clamp(self.zoom_pct + self.zoom_rate * ZOOM_RATE_PCT_S * dt, 0.0, 100.0)
        if self.focus_rate:
            self.focus_pct = _clamp(self.focus_pct + self.focus_rate * ZOOM_RATE_PCT_S * dt, 0.0, 100.0)
        if not self._may_shoot(now):
            return []
        if self.pending:
            self.pending -= 1
            return [self._shoot(now, pose)]
        if self.remaining:
            if self.last_photo_s is None or now - self.last_photo_s >= self.interval_s - 1e-9:
                if self.remaining > 0:
                    self.remaining -= 1
                if self.remaining == 0:
                    self.interval_s = 0.0
                return [self._shoot(now, pose)]
            return []
        if self.trigger_distance_m > 0:
            if self._last_trigger_at is None:
                self._last_trigger_at = (pose.lat, pose.lon)
            elif distance_m(*self._last_trigger_at, pose.lat, pose.lon) >= self.trigger_distance_m:
                return [self._shoot(now, pose)]
        return []

    def next_deadline(self) -> float | None:
        """When the next photo may be due without a command (None: only on motion or a command)."""
        if self.pending:
            return self._last_s if self.last_photo_s is None else self.last_photo_s + MIN_INTERVAL_S
        if self.remaining:
            return self._last_s if self.last_photo_s is None else self.last_photo_s + self.interval_s
        return None

    # --- what it reports -------------------------------------------------------------------------
    @property
    def focal_length_mm(self) -> float:
        lo, hi = FOCAL_LENGTH_MM
        return lo + (hi - lo) * self.zoom_pct / 100.0

    def image_status(self) -> int:
        """CAMERA_CAPTURE_STATUS.image_status: 0 idle, 1 capturing, 2 interval set but idle, 3 interval capturing."""
        if self.remaining:
            return 3
        return 1 if self.pending else 0

    def recording_ms(self, now: float) -> int:
        return 0 if self.recording_since_s is None else int((now - self.recording_since_s) * 1000)

    def available_mib(self) -> float:
        return max(0.0, STORAGE_TOTAL_MIB - self.used_bytes / 1048576.0)
