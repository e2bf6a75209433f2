"""AntennaTracker: MAV_TYPE_ANTENNA_TRACKER, the tracker's modes, a mount that points.

In AUTO it points at the vehicle it tracks (GLOBAL_POSITION_INT from SYSID_TARGET, or the
first vehicle heard when 0); GUIDED points at the location of DO_SET_ROI; SCAN sweeps; STOP
holds; MANUAL follows the sticks. Parameters: YAW_SLEW_TIME, PITCH_SLEW_TIME (s for 360 and
180 degrees), PITCH_MIN, PITCH_MAX (deg), SCAN_SPEED_YAW (deg/s), SYSID_TARGET. No missions
(MISSION_CURRENT is not sent), no fence, no takeoff.
"""

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.autopilot.settings import Behaviour as B
from gcsd.vehicle.autopilot.settings import Settings
from gcsd.vehicle.sim import Limits, TrackerDynamics
from gcsd.vehicle.types import prearm
from gcsd.vehicle.types.base import VehicleType, modes_named, stream_rates
from gcsd.vehicle.types.modes import mode_mapping

_modes = mode_mapping("tracker")
_by_name = {v: k for k, v in _modes.items()}

# AntennaTracker 4.6's parameters this module's settings() reads (all of them: params/data/tracker.tsv).
PARAMS = ("YAW_SLEW_TIME", "PITCH_SLEW_TIME", "PITCH_MIN", "PITCH_MAX", "SCAN_SPEED_YAW", "SYSID_TARGET")
MIN_SLEW_S = 0.1  # ArduPilot's range allows 0; the simulation divides by it


def settings(get) -> Settings:
    limits = Limits(
        yaw_rate_dps=360.0 / max(float(get("YAW_SLEW_TIME")), MIN_SLEW_S),
        climb_ms=180.0 / max(float(get("PITCH_SLEW_TIME")), MIN_SLEW_S),
        pitch_min_deg=float(get("PITCH_MIN")), pitch_max_deg=float(get("PITCH_MAX")), cruise_current_a=1.0,
        hover_throttle=0.3,
    )
    return Settings(limits=limits, rtl_lands=False, ignore_alt_for_waypoints=True,
                    track_sysid=int(get("SYSID_TARGET")), extra={"scan_rate_dps": float(get("SCAN_SPEED_YAW"))})


TRACKER = VehicleType(
    name="tracker",
    firmware="AntennaTracker",
    mav_type=M.MAV_TYPE_ANTENNA_TRACKER,
    modes=_modes,
    initial_mode=_by_name["MANUAL"],
    capabilities=M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
    guided_modes=frozenset({_by_name["GUIDED"], _by_name["AUTO"]}),
    manual_modes=frozenset({_by_name["MANUAL"]}),
    behaviours=modes_named(_modes, MANUAL=B.MANUAL, STOP=B.HOLD, SCAN=B.SCAN, GUIDED=B.GUIDED, AUTO=B.TRACK,
                           INITIALISING=B.IDLE),
    dynamics=TrackerDynamics,
    params=PARAMS,
    settings=settings,
    prearm_checks=prearm.TRACKER_CHECKS,
    not_produced=frozenset({M.MAVLINK_MSG_ID_MISSION_CURRENT}),
    ardupilot_stream_rates=stream_rates(1, 1, 1, 1, 1, 1, 1, 1, 10, 0),
)
