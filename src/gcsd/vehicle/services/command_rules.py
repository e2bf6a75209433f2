"""What each command does with its seven parameters: the table the edge check reads.

A command carries params 1-4 (floats) and 5-7 (COMMAND_LONG: floats; COMMAND_INT: x and y int32,
z float). `CommandService` checks them once, before any handler runs, so no handler sees a value
it cannot honour and no such value reaches the vehicle's state or a stored file:

- A parameter the command does not use (not in `uses`) is ignored whatever it holds, as
  ArduPilot ignores it (MAVLink fills reserved parameters with 0 or NaN); the handler gets 0.
- A parameter it uses must be a finite number: NaN or infinity -> DENIED (MAV_RESULT's "supported
  but invalid parameters"). Except `nan_ok`, where ArduPilot gives NaN a meaning and the handler
  gets the NaN: yaw "NaN: keep the current heading mode" (DO_REPOSITION, NAV_TAKEOFF), speed and
  loiter radius "NaN: default" (DO_REPOSITION), ARM_DISARM param1/param2 (ArduPilot compares them
  with 1, 0 and the force magics, so NaN is UNSUPPORTED / not forced), and the handlers that
  already treat NaN as "not given" (PREFLIGHT_CALIBRATION, STORAGE_FORMAT, REBOOT...).
  Infinity means nothing anywhere: DENIED.
- `limits`: used parameters with an absolute bound: altitudes within ArduPilot's Location range,
  +-83 000 m (LOCATION_ALT_MAX_M); beyond -> DENIED.
- `location`: params 5-7 are a position. Latitude within +-90 degrees and longitude +-180
  (else `bad_latlng`: DENIED as ArduPilot's check_latlng, FAILED for DO_SET_HOME whose set_home
  refuses it), altitude finite and within +-83 000 m and a global frame (GLOBAL, RELATIVE_ALT,
  TERRAIN_ALT or their _INT forms; else DENIED, ArduPilot's location_from_command_t). x = y = 0 means "here" / "none" for these commands and passes.
  `location_unused(values)`: when the position is not used (DO_SET_HOME param1 1 or x = y = 0,
  where ArduPilot takes the current position before looking at the location), it is not checked.
- A command that has no entry here uses all seven: any NaN or infinity -> DENIED. A handler that
  nobody described gets the strict default, never a value it was not written for.

Decision (the issue is silent): ArduPilot does not refuse NaN in a used command parameter; it
casts it (an undefined float-to-int conversion in C, 0 on ARM hardware). gcsd refuses it instead,
with DENIED, because a ground station that sends NaN where a value is needed has a bug the
operator should see, and a silent 0 can mean "disarm" or "mode 0".
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission.items import GLOBAL_FRAMES, LOCATION_ALT_MAX_M, lat_ok, lon_ok

ALL = frozenset(range(1, 8))
LOCATION = frozenset({5, 6, 7})
DENIED, FAILED = M.MAV_RESULT_DENIED, M.MAV_RESULT_FAILED
Values = tuple[float, float, float, float, float, float, float]  # params 1-4, x, y, z


@dataclass(frozen=True, slots=True)
class Rule:
    uses: frozenset[int] = ALL
    nan_ok: frozenset[int] = frozenset()
    limits: Mapping[int, float] = field(default_factory=dict)
    location: bool = False
    location_unused: Callable[[Values], bool] | None = None
    bad_latlng: int = DENIED


def rule(uses: str = "", nan_ok: str = "", limits: Mapping[int, float] | None = None, location: bool = False,
         location_unused: Callable[[Values], bool] | None = None, bad_latlng: int = DENIED) -> Rule:
    """A Rule from digit strings: rule(uses="12", nan_ok="2") uses params 1 and 2, NaN allowed in 2."""
    used = frozenset(int(c) for c in uses) | (LOCATION if location else frozenset())
    return Rule(used, frozenset(int(c) for c in nan_ok), dict(limits or {}), location, location_unused, bad_latlng)


NOTHING = rule()
STRICT = Rule()
ALT = {7: LOCATION_ALT_MAX_M}


def _home_here(v: Values) -> bool:
    return v[0] >= 1 or (v[4] == 0 and v[5] == 0)


RULES: dict[int, Rule] = {
    # vehicle control (services/control.py)
    M.MAV_CMD_COMPONENT_ARM_DISARM: rule("12", nan_ok="12"),
    M.MAV_CMD_DO_SET_MODE: rule("12"),
    M.MAV_CMD_GET_HOME_POSITION: NOTHING,
    M.MAV_CMD_DO_SEND_BANNER: NOTHING,
    # flying (services/flight.py)
    M.MAV_CMD_NAV_RETURN_TO_LAUNCH: NOTHING,
    M.MAV_CMD_NAV_LAND: NOTHING,
    M.MAV_CMD_NAV_LOITER_UNLIM: NOTHING,
    M.MAV_CMD_MISSION_START: rule("1"),
    M.MAV_CMD_DO_REPOSITION: rule("1234", nan_ok="134", location=True),
    M.MAV_CMD_DO_CHANGE_SPEED: rule("2"),
    M.MAV_CMD_DO_CHANGE_ALTITUDE: rule("12", limits={1: LOCATION_ALT_MAX_M}),
    M.MAV_CMD_DO_SET_HOME: rule("1", nan_ok="1", location=True, location_unused=_home_here, bad_latlng=FAILED),
    M.MAV_CMD_DO_SET_ROI: rule(location=True),
    M.MAV_CMD_DO_SET_ROI_LOCATION: rule(location=True),
    M.MAV_CMD_DO_SET_ROI_NONE: NOTHING,
    M.MAV_CMD_CONDITION_YAW: rule("1234"),
    M.MAV_CMD_DO_PAUSE_CONTINUE: rule("1"),
    M.MAV_CMD_DO_SET_SERVO: rule("12"),
    M.MAV_CMD_DO_REPEAT_SERVO: rule("1234"),
    M.MAV_CMD_DO_SET_RELAY: rule("12"),
    M.MAV_CMD_DO_REPEAT_RELAY: rule("123"),
    M.MAV_CMD_DO_FLIGHTTERMINATION: rule("1"),
    M.MAV_CMD_DO_JUMP_TAG: rule("1"),
    M.MAV_CMD_DO_FENCE_ENABLE: rule("1"),
    # per vehicle type (vehicles/commands.py)
    M.MAV_CMD_NAV_TAKEOFF: rule("47", nan_ok="4", limits=ALT),
    M.MAV_CMD_DO_LAND_START: NOTHING,
    M.MAV_CMD_DO_MOTOR_TEST: rule("1234"),
    M.MAV_CMD_DO_SET_REVERSE: rule("1"),
    # maintenance (services/maintenance.py): these handlers read NaN as "not given"
    M.MAV_CMD_PREFLIGHT_CALIBRATION: rule("123456", nan_ok="123456"),
    M.MAV_CMD_STORAGE_FORMAT: rule("12", nan_ok="12"),
    M.MAV_CMD_PREFLIGHT_STORAGE: rule("1", nan_ok="1"),
    M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: rule("1", nan_ok="1"),
    M.MAV_CMD_RUN_PREARM_CHECKS: NOTHING,
    M.MAV_CMD_DO_START_MAG_CAL: rule("12345", nan_ok="12345"),
    M.MAV_CMD_DO_ACCEPT_MAG_CAL: rule("1"),  # param1: the compass mask (MAVProxy accepts one at a time)
    M.MAV_CMD_ACCELCAL_VEHICLE_POS: rule("1"),
    M.MAV_CMD_DO_CANCEL_MAG_CAL: NOTHING,
    M.MAV_CMD_FIXED_MAG_CAL_YAW: rule("1"),
    # message rates (services/rates.py), missions, high latency
    M.MAV_CMD_SET_MESSAGE_INTERVAL: rule("123"),
    M.MAV_CMD_GET_MESSAGE_INTERVAL: rule("1"),
    M.MAV_CMD_REQUEST_MESSAGE: rule("12"),
    M.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: rule("1"),
    M.MAV_CMD_DO_SET_MISSION_CURRENT: rule("12"),
    M.MAV_CMD_CONTROL_HIGH_LATENCY: rule("1"),
    # payload commands (services/peripherals.py): what ArduPilot's libraries read
    M.MAV_CMD_DO_GRIPPER: rule("12"),
    M.MAV_CMD_DO_PARACHUTE: rule("1"),
    M.MAV_CMD_AIRFRAME_CONFIGURATION: rule("12"),
    M.MAV_CMD_DO_SET_SAFETY_SWITCH_STATE: rule("1"),
    M.MAV_CMD_BATTERY_RESET: rule("12"),
    getattr(M, "MAV_CMD_EXTERNAL_WIND_ESTIMATE", 43004): rule("1234"),
    M.MAV_CMD_SET_EKF_SOURCE_SET: rule("1"),
    M.MAV_CMD_DO_FOLLOW: rule("1"),
    M.MAV_CMD_DO_SET_ROI_SYSID: rule("1"),
    M.MAV_CMD_CAN_FORWARD: rule("1"),
    M.MAV_CMD_DEBUG_TRAP: rule("4"),
    M.MAV_CMD_DO_AUX_FUNCTION: rule("12"),
    M.MAV_CMD_SCRIPTING: rule("1"),
    # the gimbal manager (gimbal/service.py): NaN angles with rates (or all NaN) mean rate control
    # or "only the yaw lock" (x = flags, z = gimbal device id); CONFIGURE's p3-p6 are unused
    M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW: rule("123457", nan_ok="1234"),
    M.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE: rule("127"),
    M.MAV_CMD_DO_MOUNT_CONTROL: rule("1234567"),
    M.MAV_CMD_DO_MOUNT_CONFIGURE: rule("1"),
    # the camera (camera/service.py): p1 is a camera or stream id where there is one
    M.MAV_CMD_IMAGE_START_CAPTURE: rule("123"),
    M.MAV_CMD_IMAGE_STOP_CAPTURE: rule("1"),
    M.MAV_CMD_VIDEO_START_CAPTURE: rule("1"),
    M.MAV_CMD_VIDEO_STOP_CAPTURE: rule("1"),
    M.MAV_CMD_SET_CAMERA_MODE: rule("2"),
    M.MAV_CMD_SET_CAMERA_ZOOM: rule("12"),
    M.MAV_CMD_SET_CAMERA_FOCUS: rule("12"),
    M.MAV_CMD_DO_DIGICAM_CONTROL: rule("5"),
    M.MAV_CMD_DO_SET_CAM_TRIGG_DIST: rule("13"),
    **{cmd: NOTHING for cmd in (
        M.MAV_CMD_REQUEST_CAMERA_INFORMATION, M.MAV_CMD_REQUEST_CAMERA_SETTINGS,
        M.MAV_CMD_REQUEST_CAMERA_CAPTURE_STATUS, M.MAV_CMD_REQUEST_STORAGE_INFORMATION,
        M.MAV_CMD_REQUEST_VIDEO_STREAM_INFORMATION, M.MAV_CMD_RESET_CAMERA_SETTINGS,
    )},
    **{cmd: NOTHING for cmd in (
        M.MAV_CMD_DO_DIGICAM_CONFIGURE, M.MAV_CMD_SET_CAMERA_SOURCE,
        M.MAV_CMD_DO_ADSB_OUT_IDENT, M.MAV_CMD_START_RX_PAIR,
        M.MAV_CMD_DO_RETURN_PATH_START, M.MAV_CMD_NAV_VTOL_LAND, M.MAV_CMD_DO_ENGINE_CONTROL,
        M.MAV_CMD_DO_VTOL_TRANSITION, M.MAV_CMD_DO_GO_AROUND, M.MAV_CMD_GUIDED_CHANGE_HEADING, M.MAV_CMD_DO_WINCH,
    )},  # answered without reading a value (no such device, or the command's own checks)
    # per vehicle type (vehicles/commands.py)
    M.MAV_CMD_NAV_VTOL_TAKEOFF: rule("7", limits=ALT),
    M.MAV_CMD_SOLO_BTN_FLY_CLICK: NOTHING,
    M.MAV_CMD_SOLO_BTN_FLY_HOLD: rule("1"),
    M.MAV_CMD_SOLO_BTN_PAUSE_CLICK: NOTHING,
    M.MAV_CMD_DO_SPRAYER: rule("1"),
    M.MAV_CMD_DO_AUTOTUNE_ENABLE: rule("1"),
    M.MAV_CMD_GUIDED_CHANGE_SPEED: rule("2"),
    M.MAV_CMD_GUIDED_CHANGE_ALTITUDE: rule("3", limits={3: LOCATION_ALT_MAX_M}),
    M.MAV_CMD_SET_HAGL: rule("123"),
}


def _latlng_ok(x: float, y: float) -> bool:
    return math.isfinite(x) and math.isfinite(y) and lat_ok(x) and lon_ok(y)


def check(rule: Rule, values: Values, frame: int) -> int | Values:
    """The MAV_RESULT that refuses `values` (in `frame`), or the values a handler gets (unused ones zeroed)."""
    out: list[float] = []
    for n, v in enumerate(values, start=1):
        if n not in rule.uses or (rule.location and n in LOCATION):
            out.append(0)
        elif math.isnan(v) and n in rule.nan_ok:
            out.append(v)
        elif not math.isfinite(v) or abs(v) > rule.limits.get(n, math.inf):
            return DENIED
        else:
            out.append(v)
    if rule.location and not (rule.location_unused is not None and rule.location_unused(values)):
        x, y, z = values[4], values[5], values[6]
        if not (math.isfinite(z) and abs(z) <= LOCATION_ALT_MAX_M) or frame not in GLOBAL_FRAMES:
            return DENIED
        if not _latlng_ok(x, y):
            return rule.bad_latlng
        out[4:7] = [x, y, z]
    return tuple(out)
