"""ArduCopter: MAV_TYPE_QUADROTOR, ArduCopter's mode numbers, the copter's capabilities."""

from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as M

from .base import VehicleType

_modes = dict(mavutil.mode_mapping_acm)
_by_name = {v: k for k, v in _modes.items()}

COPTER = VehicleType(
    name="copter",
    mav_type=M.MAV_TYPE_QUADROTOR,
    modes=_modes,
    initial_mode=_by_name["STABILIZE"],
    capabilities=M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
    guided_modes=frozenset({_by_name["GUIDED"], _by_name["AUTO"], _by_name["RTL"], _by_name["LAND"]}),
    manual_modes=frozenset({_by_name["ACRO"]}),
    # ArduCopter arms in manual-throttle and position modes, not in AUTO/RTL/LAND/BRAKE etc.
    armable_modes=frozenset(
        _by_name[n] for n in ("STABILIZE", "ACRO", "ALT_HOLD", "GUIDED", "LOITER", "POSHOLD", "DRIFT", "SPORT", "FLOWHOLD", "ZIGZAG")
    ),
)
