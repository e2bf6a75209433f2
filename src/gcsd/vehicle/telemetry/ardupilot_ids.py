"""The MAVLink messages ArduPilot maps to one of its `ap_message`s (GCS_Common.cpp,
`GCS_MAVLINK::mavlink_id_to_ap_message_id`, as in the ArduPilot source checked for issue 27): SET_MESSAGE_INTERVAL and
GET_MESSAGE_INTERVAL take every one of them (Cockpit asks for 36 at connect), whether or not
gcsd has a producer for it; the message is sent where it has one (telemetry/producers.py, a
gimbal's), as ArduPilot sends what its build has. An id not listed and without a producer is
DENIED. The union over ArduPilot's vehicles and build options (ArduPlane's AOA_SSA and
DEEPSTALL, Rover's WATER_DEPTH...), since a ground station asks whichever vehicle it sees.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as M

AVAILABLE_MODES, AVAILABLE_MODES_MONITOR = 435, 437  # current MAVLink; pymavlink's dialect lacks them

MAPPED_NAMES = (
    "ADSB_VEHICLE", "AHRS", "AHRS2", "AIRSPEED", "AIS_VESSEL", "AOA_SSA", "ATTITUDE",
    "ATTITUDE_QUATERNION", "ATTITUDE_TARGET", "AUTOPILOT_STATE_FOR_GIMBAL_DEVICE", "AUTOPILOT_VERSION",
    "BATTERY_STATUS", "CAMERA_CAPTURE_STATUS", "CAMERA_FEEDBACK", "CAMERA_FOV_STATUS",
    "CAMERA_INFORMATION", "CAMERA_SETTINGS", "CAMERA_THERMAL_RANGE", "DEEPSTALL", "DISTANCE_SENSOR",
    "EFI_STATUS", "EKF_STATUS_REPORT", "ESC_TELEMETRY_1_TO_4", "EXTENDED_SYS_STATE", "FENCE_STATUS",
    "FLIGHT_INFORMATION", "GENERATOR_STATUS", "GIMBAL_DEVICE_ATTITUDE_STATUS",
    "GIMBAL_MANAGER_INFORMATION", "GIMBAL_MANAGER_STATUS", "GLOBAL_POSITION_INT", "GPS2_RAW",
    "GPS2_RTK", "GPS_GLOBAL_ORIGIN", "GPS_RAW_INT", "GPS_RTK", "HEARTBEAT", "HIGHRES_IMU",
    "HIGH_LATENCY2", "HOME_POSITION", "HWSTATUS", "LOCAL_POSITION_NED", "MAG_CAL_PROGRESS",
    "MAG_CAL_REPORT", "MCU_STATUS", "MEMINFO", "MISSION_CURRENT", "MISSION_ITEM_REACHED",
    "NAV_CONTROLLER_OUTPUT", "OPTICAL_FLOW", "PARAM_VALUE", "PID_TUNING", "POSITION_TARGET_GLOBAL_INT",
    "POSITION_TARGET_LOCAL_NED", "POWER_STATUS", "RANGEFINDER", "RAW_IMU", "RC_CHANNELS",
    "RC_CHANNELS_RAW", "RC_CHANNELS_SCALED", "RELAY_STATUS", "RPM", "SCALED_IMU", "SCALED_IMU2",
    "SCALED_IMU3", "SCALED_PRESSURE", "SCALED_PRESSURE2", "SCALED_PRESSURE3", "SERVO_OUTPUT_RAW",
    "SIMSTATE", "SIM_STATE", "SYSTEM_TIME", "SYS_STATUS", "TERRAIN_REPORT", "TERRAIN_REQUEST",
    "UAVIONIX_ADSB_OUT_STATUS", "VFR_HUD", "VIBRATION", "VIDEO_STREAM_INFORMATION", "WATER_DEPTH",
    "WINCH_STATUS", "WIND",
)

ARDUPILOT_MAPPED: frozenset[int] = frozenset(
    {getattr(M, f"MAVLINK_MSG_ID_{name}") for name in MAPPED_NAMES} | {AVAILABLE_MODES, AVAILABLE_MODES_MONITOR}
)
