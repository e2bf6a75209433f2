"""A companion computer: MAV_TYPE_ONBOARD_CONTROLLER, compid 191 by default.

It offers its own component (parameters, FTP, signing, commands) beside a flight controller:
it has no modes, nothing to arm and nothing that moves, so it sends no position, attitude,
GPS, RC, servo or mission telemetry, and refuses ARM_DISARM (arming is the flight
controller's business).
"""

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.types.base import VehicleType

NOT_PRODUCED = frozenset({
    M.MAVLINK_MSG_ID_GPS_RAW_INT, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
    M.MAVLINK_MSG_ID_ATTITUDE, M.MAVLINK_MSG_ID_AHRS, M.MAVLINK_MSG_ID_AHRS2, M.MAVLINK_MSG_ID_SIMSTATE,
    M.MAVLINK_MSG_ID_VFR_HUD, M.MAVLINK_MSG_ID_RAW_IMU, M.MAVLINK_MSG_ID_SCALED_IMU2,
    M.MAVLINK_MSG_ID_SCALED_PRESSURE, M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, M.MAVLINK_MSG_ID_RC_CHANNELS,
    M.MAVLINK_MSG_ID_RC_CHANNELS_RAW, M.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT, M.MAVLINK_MSG_ID_MISSION_CURRENT,
    M.MAVLINK_MSG_ID_WIND, M.MAVLINK_MSG_ID_EKF_STATUS_REPORT, M.MAVLINK_MSG_ID_VIBRATION,
    M.MAVLINK_MSG_ID_BATTERY_STATUS, M.MAVLINK_MSG_ID_HOME_POSITION, M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, M.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT,
    M.MAVLINK_MSG_ID_FENCE_STATUS, M.MAVLINK_MSG_ID_HIGH_LATENCY2,
})

COMPANION = VehicleType(
    name="companion",
    mav_type=M.MAV_TYPE_ONBOARD_CONTROLLER,
    modes={0: "NONE"},
    initial_mode=0,
    capabilities=M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
    not_produced=NOT_PRODUCED,
    can_arm=False,
)
