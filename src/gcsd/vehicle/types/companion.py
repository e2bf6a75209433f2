"""A companion computer: MAV_TYPE_ONBOARD_CONTROLLER, compid 191 by default.

It offers its own component (parameters, FTP, signing, commands, flight logs) beside a flight
controller and says what it is as ArduPilot and MAVLink expect of a companion: HEARTBEAT
autopilot MAV_AUTOPILOT_INVALID, base_mode 0, system_status ACTIVE, so MAVProxy, MAVSDK and
QGroundControl take the flight controller as the vehicle (an ARDUPILOTMEGA heartbeat from
1/191 made MAVProxy target it and MAVSDK flip its vehicle type: issue 27). It has no modes,
nothing to arm and nothing that moves: it never sends position, attitude, GPS, RC, servo,
battery, home or mission telemetry (NOT_PRODUCED; SET_MESSAGE_INTERVAL and REQUEST_MESSAGE for
them are DENIED / FAILED), and refuses ARM_DISARM (arming is the flight controller's business).
Its streams carry nothing but the HEARTBEAT: SYS_STATUS, POWER_STATUS, MEMINFO and SYSTEM_TIME,
which ArduPilot would forward to every ground station as a second vehicle's, go out only to a
client that asks the companion's component for them (NOT_STREAMED). It has no mission, fence,
rally point or home (`has_mission`): they are the flight controller's; a mission request
addressed to the companion's component is answered MAV_MISSION_UNSUPPORTED, never with the
default `vehicle.home` (services/mission.py).
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
    M.MAVLINK_MSG_ID_FENCE_STATUS, M.MAVLINK_MSG_ID_HIGH_LATENCY2, M.MAVLINK_MSG_ID_SCALED_IMU3,
    M.MAVLINK_MSG_ID_SCALED_PRESSURE2, M.MAVLINK_MSG_ID_SCALED_PRESSURE3, M.MAVLINK_MSG_ID_GPS2_RAW,
    M.MAVLINK_MSG_ID_GPS_RTK, M.MAVLINK_MSG_ID_GPS2_RTK, M.MAVLINK_MSG_ID_RANGEFINDER,
    M.MAVLINK_MSG_ID_DISTANCE_SENSOR, M.MAVLINK_MSG_ID_OPTICAL_FLOW, M.MAVLINK_MSG_ID_PID_TUNING,
    M.MAVLINK_MSG_ID_FLIGHT_INFORMATION,
})

NOT_STREAMED = frozenset({
    M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_POWER_STATUS, M.MAVLINK_MSG_ID_MEMINFO,
    M.MAVLINK_MSG_ID_SYSTEM_TIME,
})

COMPANION = VehicleType(
    name="companion",
    mav_type=M.MAV_TYPE_ONBOARD_CONTROLLER,
    modes={0: "NONE"},
    initial_mode=0,
    capabilities=M.MAV_PROTOCOL_CAPABILITY_COMMAND_INT,
    not_produced=NOT_PRODUCED,
    not_streamed=NOT_STREAMED,
    autopilot=M.MAV_AUTOPILOT_INVALID,
    has_mission=False,
    can_arm=False,
)
