"""The ten SRn_ telemetry streams: which messages each carries, as data.

Membership follows ArduPilot's GCS_MAVLink_Parameters.cpp (shared by all vehicles since 4.7),
limited to messages gcsd can produce; a message with no producer for a vehicle is skipped.
REQUEST_DATA_STREAM ids map to streams as in GCS_Param.cpp: 0 (ALL) sets every stream except
PARAMS and ADSB; 5, 7, 8, 9 and the PARAMS/ADSB streams are not settable that way.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as mavlink

STREAM_NAMES = ("raw_sens", "ext_stat", "rc_chan", "raw_ctrl", "position", "extra1", "extra2", "extra3", "params", "adsb")
PARAM_SUFFIX = {
    "raw_sens": "RAW_SENS", "ext_stat": "EXT_STAT", "rc_chan": "RC_CHAN", "raw_ctrl": "RAW_CTRL",
    "position": "POSITION", "extra1": "EXTRA1", "extra2": "EXTRA2", "extra3": "EXTRA3",
    "params": "PARAMS", "adsb": "ADSB",
}

_M = mavlink
STREAM_MESSAGES: dict[str, tuple[int, ...]] = {
    "raw_sens": (_M.MAVLINK_MSG_ID_RAW_IMU, _M.MAVLINK_MSG_ID_SCALED_IMU2, _M.MAVLINK_MSG_ID_SCALED_PRESSURE),
    "ext_stat": (
        _M.MAVLINK_MSG_ID_SYS_STATUS, _M.MAVLINK_MSG_ID_POWER_STATUS, _M.MAVLINK_MSG_ID_MEMINFO,
        _M.MAVLINK_MSG_ID_MISSION_CURRENT, _M.MAVLINK_MSG_ID_GPS_RAW_INT,
        _M.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT, _M.MAVLINK_MSG_ID_FENCE_STATUS,
        _M.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT,
    ),
    "rc_chan": (_M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, _M.MAVLINK_MSG_ID_RC_CHANNELS, _M.MAVLINK_MSG_ID_RC_CHANNELS_RAW),
    "raw_ctrl": (_M.MAVLINK_MSG_ID_RC_CHANNELS_SCALED,),
    "position": (_M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, _M.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
    "extra1": (_M.MAVLINK_MSG_ID_ATTITUDE, _M.MAVLINK_MSG_ID_SIMSTATE, _M.MAVLINK_MSG_ID_AHRS2),
    "extra2": (_M.MAVLINK_MSG_ID_VFR_HUD,),
    "extra3": (
        _M.MAVLINK_MSG_ID_AHRS, _M.MAVLINK_MSG_ID_WIND, _M.MAVLINK_MSG_ID_SYSTEM_TIME,
        _M.MAVLINK_MSG_ID_BATTERY_STATUS, _M.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS,  # with a gimbal
        _M.MAVLINK_MSG_ID_EKF_STATUS_REPORT, _M.MAVLINK_MSG_ID_VIBRATION,
    ),
    "params": (),  # a list download is streamed by ParamService.pending, paced by the link, not a bucket
    "adsb": (_M.MAVLINK_MSG_ID_ADSB_VEHICLE,),
}

STREAM_OF_MESSAGE: dict[int, str] = {m: s for s, ids in STREAM_MESSAGES.items() for m in ids}

# REQUEST_DATA_STREAM.req_stream_id -> stream names it sets
REQUEST_DATA_STREAM_IDS: dict[int, tuple[str, ...]] = {
    _M.MAV_DATA_STREAM_ALL: tuple(s for s in STREAM_NAMES if s not in ("params", "adsb")),
    _M.MAV_DATA_STREAM_RAW_SENSORS: ("raw_sens",),
    _M.MAV_DATA_STREAM_EXTENDED_STATUS: ("ext_stat",),
    _M.MAV_DATA_STREAM_RC_CHANNELS: ("rc_chan",),
    _M.MAV_DATA_STREAM_RAW_CONTROLLER: ("raw_ctrl",),
    _M.MAV_DATA_STREAM_POSITION: ("position",),
    _M.MAV_DATA_STREAM_EXTRA1: ("extra1",),
    _M.MAV_DATA_STREAM_EXTRA2: ("extra2",),
    _M.MAV_DATA_STREAM_EXTRA3: ("extra3",),
}


def rate_to_interval_ms(rate_hz: float) -> int:
    """Stream rate to bucket interval as ArduPilot does it: 1000/rate, whole ms; 0 Hz -> 0 (off)."""
    if rate_hz <= 0:
        return 0
    return min(int(1000 / rate_hz), 60_000)
