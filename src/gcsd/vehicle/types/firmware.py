"""The ArduPilot release gcsd reports, one for every vehicle type: 4.6.3, official.

Ground stations choose their parameter metadata by the version in AUTOPILOT_VERSION
(QGroundControl loads APMParameterFactMetaData.<Vehicle>.4.6.xml) and show the banner
STATUSTEXTs, so the version, the banner and the parameter names (ArduPilot 4.6's:
params/data/) must agree. 4.6.3 is the 4.6 stable release whose banner reads
"ArduCopter V4.6.3 (3fc7011a)" (the same commit for ArduPlane and ArduRover).

- AUTOPILOT_VERSION.flight_sw_version as ArduPilot encodes it: major << 24 | minor << 16 |
  patch << 8 | FIRMWARE_VERSION_TYPE_OFFICIAL (255); flight_custom_version: the first 8
  characters of the git hash, as ASCII bytes.
- The banner (GCS_MAVLINK::send_banner): "<firmware> V4.6.3 (3fc7011a)", then the vehicle's own
  lines: a copter adds "Frame: <CLASS>/<TYPE>" from FRAME_CLASS and FRAME_TYPE with
  AP_MotorsMatrix's names. The board and OS lines of a real flight controller ("ChibiOS: ...",
  the board id) are not sent: gcsd is no board, and ArduPilot SITL does not send them either.
- Sub and Blimp have no 4.6 stable release; gcsd still reports 4.6.3 for them (one release for
  the daemon), with the nearest published parameter metadata (Sub-4.5, Blimp-4.7).
"""

from __future__ import annotations

from collections.abc import Callable

from pymavlink.dialects.v20 import ardupilotmega as M

VERSION = (4, 6, 3)
GIT_HASH = "3fc7011a"
FLIGHT_SW_VERSION = (VERSION[0] << 24) | (VERSION[1] << 16) | (VERSION[2] << 8) | M.FIRMWARE_VERSION_TYPE_OFFICIAL
FLIGHT_CUSTOM_VERSION = GIT_HASH.encode()[:8]

# AP_Motors: FRAME_CLASS -> (name, motors), FRAME_TYPE -> name (get_frame_string / get_type_string).
FRAME_CLASSES = {
    0: ("UNDEFINED", 0), 1: ("QUAD", 4), 2: ("HEXA", 6), 3: ("OCTA", 8), 4: ("OCTAQUAD", 8), 5: ("Y6", 6),
    6: ("HELI", 1), 7: ("TRI", 3), 8: ("SINGLE", 1), 9: ("COAX", 2), 10: ("BICOPTER", 2), 11: ("HELI_DUAL", 2),
    12: ("DODECAHEXA", 12), 13: ("HELI_QUAD", 4), 14: ("DECA", 10), 15: ("SCRIPTING", 0), 16: ("6DOF_SCRIPTING", 0),
    17: ("DYNAMIC_SCRIPTING", 0),
}
FRAME_TYPES = {
    0: "PLUS", 1: "X", 2: "V", 3: "H", 4: "VTAIL", 5: "ATAIL", 6: "PLUSREV", 10: "Y6B", 11: "Y6F", 12: "BF_X",
    13: "DJI_X", 14: "CW_X", 15: "I", 16: "NYT_PLUS", 17: "NYT_X", 18: "BF_X_REV", 19: "Y4",
}


def version_string(firmware: str) -> str:
    return f"{firmware} V{VERSION[0]}.{VERSION[1]}.{VERSION[2]} ({GIT_HASH})"


def copter_frame(get: Callable[[str], float]) -> list[str]:
    """ArduCopter's frame line, e.g. "Frame: QUAD/X"."""
    name = FRAME_CLASSES.get(int(get("FRAME_CLASS")), ("UNKNOWN", 0))[0]
    return [f"Frame: {name}/{FRAME_TYPES.get(int(get('FRAME_TYPE')), 'UNKNOWN')}"]


def motor_count(get: Callable[[str], float]) -> int:
    """How many motors FRAME_CLASS drives (AP_MotorsMatrix's setup for that class)."""
    return FRAME_CLASSES.get(int(get("FRAME_CLASS")), ("", 0))[1]
