"""Telemetry producers: one function per message id, reading the vehicle through a TelemetryView.

`BASE_PRODUCERS[msgid](view, channel, now)` returns the message to send, or None when there is
nothing to say (no home yet, a MAVLink2-only message on a MAVLink1 link...). Which ids a
channel sends and how often is the scheduler's business; what they contain is decided here.
A message id without a producer cannot be streamed or requested (REQUEST_MESSAGE: FAILED);
SET_MESSAGE_INTERVAL takes it if ArduPilot maps it (ardupilot_ids.py) and sends nothing.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.sim.geo import deg_e7
from gcsd.vehicle.types.firmware import FLIGHT_CUSTOM_VERSION, FLIGHT_SW_VERSION
from gcsd.vehicle.types.health import sensor_bits, system_status
from gcsd.wire.codec import MAVLink_message

if TYPE_CHECKING:
    from gcsd.links.channel import Channel
    from gcsd.vehicle.telemetry.view import TelemetryView

Producer = Callable[["TelemetryView", "Channel", float], MAVLink_message | None]



def heartbeat(ctx, channel, now):
    s = ctx.state
    v = ctx.vehicle
    return M.MAVLink_heartbeat_message(
        v.mav_type, v.autopilot, v.base_mode(s), s.mode, system_status(ctx), 3
    )


def sys_status(ctx, channel, now):
    """Sensor bits as ArduPilot sets them, from the vehicle's real state (gcsd.vehicle.types.health)."""
    s = ctx.state
    present, enabled, healthy = sensor_bits(ctx)
    volts_mv, current_ca, remaining = 0, -1, -1  # no battery monitor (BATT_MONITOR 0), as ArduPilot
    if battery_monitored(ctx):
        volts_mv, current_ca, remaining = int(s.battery_voltage_v * 1000), int(s.current_a * 100), s.battery_remaining_pct
    return M.MAVLink_sys_status_message(
        present, enabled, healthy, 100, volts_mv, current_ca, remaining, 0, ctx.comm_error_count(), 0, 0, 0, 0,
    )


def power_status(ctx, channel, now):
    return M.MAVLink_power_status_message(5000, 5000, M.MAV_POWER_STATUS_BRICK_VALID)


def meminfo(ctx, channel, now):
    return M.MAVLink_meminfo_message(65535, 65535, 1 << 20)


def gps_raw_int(ctx, channel, now):
    s = ctx.state
    cog = int(s.heading_deg * 100) if s.groundspeed_ms > 0.2 else 65535
    return M.MAVLink_gps_raw_int_message(
        ctx.time_usec(now), s.gps_fix_type, deg_e7(s.lat), deg_e7(s.lon), int(s.alt_amsl_m * 1000),
        int(s.hdop * 100), int(s.hdop * 150), int(s.groundspeed_ms * 100), cog, s.satellites,
    )


def global_position_int(ctx, channel, now):
    s = ctx.state
    return M.MAVLink_global_position_int_message(
        ctx.time_boot_ms(now), deg_e7(s.lat), deg_e7(s.lon), int(s.alt_amsl_m * 1000), int(s.relative_alt_m * 1000),
        int(s.vn_ms * 100), int(s.ve_ms * 100), int(s.vd_ms * 100), int(s.heading_deg * 100) % 36000,
    )


def local_position_ned(ctx, channel, now):
    s = ctx.state
    north = math.radians(s.lat - s.home_lat) * 6378137.0
    east = math.radians(s.lon - s.home_lon) * 6378137.0 * math.cos(math.radians(s.home_lat))
    return M.MAVLink_local_position_ned_message(
        ctx.time_boot_ms(now), north, east, -s.relative_alt_m, s.vn_ms, s.ve_ms, s.vd_ms
    )


def attitude(ctx, channel, now):
    s = ctx.state
    return M.MAVLink_attitude_message(ctx.time_boot_ms(now), s.roll_rad, s.pitch_rad, s.yaw_rad, 0.0, 0.0, 0.0)


def ahrs2(ctx, channel, now):
    s = ctx.state
    return M.MAVLink_ahrs2_message(s.roll_rad, s.pitch_rad, s.yaw_rad, s.alt_amsl_m, deg_e7(s.lat), deg_e7(s.lon))


def simstate(ctx, channel, now):
    s = ctx.state
    return M.MAVLink_simstate_message(s.roll_rad, s.pitch_rad, s.yaw_rad, 0, 0, -9.81, 0, 0, 0, deg_e7(s.lat), deg_e7(s.lon))


def vfr_hud(ctx, channel, now):
    s = ctx.state
    return M.MAVLink_vfr_hud_message(
        s.airspeed_ms, s.groundspeed_ms, int(s.heading_deg), s.throttle_pct, s.alt_amsl_m, -s.vd_ms  # alt is AMSL
    )


def system_time(ctx, channel, now):
    return M.MAVLink_system_time_message(int(ctx.wall() * 1e6), ctx.time_boot_ms(now))


def battery_monitored(ctx) -> bool:
    """BATT_MONITOR 0: no battery monitor, so no BATTERY_STATUS and no battery in SYS_STATUS; a
    component without the parameter (a companion computer) has no battery either."""
    return "BATT_MONITOR" in ctx.params and ctx.params.get("BATT_MONITOR") != 0


def battery_status(ctx, channel, now):
    if not battery_monitored(ctx):
        return None
    s = ctx.state
    cells = [int(s.battery_voltage_v * 1000 / 4)] * 4 + [65535] * 6
    return M.MAVLink_battery_status_message(
        0, M.MAV_BATTERY_FUNCTION_ALL, M.MAV_BATTERY_TYPE_LIPO, 32767, cells, int(s.current_a * 100),
        int(s.consumed_mah), -1, s.battery_remaining_pct,
    )


def raw_imu(ctx, channel, now):
    return M.MAVLink_raw_imu_message(ctx.time_usec(now), 0, 0, -1000, 0, 0, 0, 200, 0, 400)


def scaled_imu2(ctx, channel, now):
    return M.MAVLink_scaled_imu2_message(ctx.time_boot_ms(now), 0, 0, -1000, 0, 0, 0, 200, 0, 400)


def scaled_pressure(ctx, channel, now):
    s = ctx.state
    press_hpa = 1013.25 * (1 - 2.25577e-5 * s.alt_amsl_m) ** 5.25588
    return M.MAVLink_scaled_pressure_message(ctx.time_boot_ms(now), press_hpa, 0.0, 2500)


MOTOR_FUNCTIONS = range(33, 41)


def _servo_pwm(ctx, n: int) -> int:
    """SERVOn_ scaling: motors follow the throttle between MIN and MAX, others sit at TRIM."""
    override = ctx.state.servo_override.get(n)  # DO_SET_SERVO, DO_REPEAT_SERVO, DO_MOTOR_TEST
    if override is not None:
        return override
    if ctx.vehicle.motor_pwm is not None:  # a multicopter: FRAME_CLASS, MOT_* (vehicles/motors.py)
        motor = ctx.vehicle.motor_pwm(ctx, n)
        if motor is not None:
            return motor
    p = ctx.params.clamped
    lo, hi = p(f"SERVO{n}_MIN"), p(f"SERVO{n}_MAX")
    if p(f"SERVO{n}_FUNCTION") in MOTOR_FUNCTIONS:
        frac = ctx.state.throttle_pct / 100.0
        if p(f"SERVO{n}_REVERSED"):
            frac = 1.0 - frac
        return int(lo + (hi - lo) * frac) if ctx.state.armed else int(lo)
    return int(p(f"SERVO{n}_TRIM")) if p(f"SERVO{n}_FUNCTION") != 0 else 0


def servo_output_raw(ctx, channel, now):
    pwm = [_servo_pwm(ctx, n) for n in range(1, 17)]
    return M.MAVLink_servo_output_raw_message(ctx.time_usec(now) & 0xFFFFFFFF, 0, *pwm)


def _rc_values(ctx, count: int) -> list[int]:
    """Each RC input at its RCn_TRIM (sticks at rest), or as RC_CHANNELS_OVERRIDE set it."""
    override = ctx.state.rc_override
    return [override.get(n) or int(ctx.params.clamped(f"RC{n}_TRIM")) for n in range(1, count + 1)]


def rc_channels(ctx, channel, now):
    return M.MAVLink_rc_channels_message(ctx.time_boot_ms(now), 16, *_rc_values(ctx, 16), 0, 0, 255)


def rc_channels_raw(ctx, channel, now):
    if not channel.mavlink1:
        return None  # ArduPilot only emits the legacy message on MAVLink1 links
    return M.MAVLink_rc_channels_raw_message(ctx.time_boot_ms(now), 0, *_rc_values(ctx, 8), 255)


def nav_controller_output(ctx, channel, now):
    s = ctx.state
    return M.MAVLink_nav_controller_output_message(
        math.degrees(s.roll_rad), math.degrees(s.pitch_rad), int(s.target_bearing_deg), int(s.target_bearing_deg),
        min(int(s.wp_dist_m), 65535), s.alt_error_m, 0, s.xtrack_error_m,
    )


def mission_current(ctx, channel, now):
    return ctx.plans.current_message()


def ahrs(ctx, channel, now):
    return M.MAVLink_ahrs_message(0, 0, 0, 0, 0, 0, 0)


def wind(ctx, channel, now):
    s = ctx.state
    speed = math.hypot(s.wind_n_ms, s.wind_e_ms)
    blowing_from = (math.degrees(math.atan2(s.wind_e_ms, s.wind_n_ms)) + 180.0) % 360.0 if speed > 0 else 0.0
    return M.MAVLink_wind_message(blowing_from, speed, 0.0)


def ekf_status_report(ctx, channel, now):
    flags = (
        M.EKF_ATTITUDE | M.EKF_VELOCITY_HORIZ | M.EKF_VELOCITY_VERT | M.EKF_POS_HORIZ_REL
        | M.EKF_POS_HORIZ_ABS | M.EKF_POS_VERT_ABS | M.EKF_PRED_POS_HORIZ_REL | M.EKF_PRED_POS_HORIZ_ABS
    )
    return M.MAVLink_ekf_status_report_message(flags, 0.01, 0.01, 0.01, 0.01, 0.0)


def vibration(ctx, channel, now):
    return M.MAVLink_vibration_message(ctx.time_usec(now), 0.1, 0.1, 0.1, 0, 0, 0)


def home_position(ctx, channel, now):
    s = ctx.state
    if not s.has_home:
        return None
    return M.MAVLink_home_position_message(
        deg_e7(s.home_lat), deg_e7(s.home_lon), int(s.home_alt_m * 1000), 0, 0, 0, [1, 0, 0, 0], 0, 0, 0,
        ctx.time_usec(now),
    )


def gps_global_origin(ctx, channel, now):
    s = ctx.state
    if not s.has_home:
        return None
    return M.MAVLink_gps_global_origin_message(deg_e7(s.home_lat), deg_e7(s.home_lon), int(s.home_alt_m * 1000), ctx.time_usec(now))


def autopilot_version(ctx, channel, now):
    caps = ctx.capabilities()
    if not channel.mavlink1:
        caps |= M.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    return M.MAVLink_autopilot_version_message(
        caps, FLIGHT_SW_VERSION, 0, 0, 0, FLIGHT_CUSTOM_VERSION, b"\0" * 8, b"\0" * 8, 0, 0, 0, [0] * 18
    )


def flight_information(ctx, channel, now):
    """As ArduPilot's send_flight_information: times in microseconds since boot (the fields are
    misnamed *_utc in MAVLink); the take-off time is noted when a send first sees the vehicle off
    the ground and cleared when one sees it landed, as ArduPilot does."""
    s = ctx.state
    if s.on_ground:
        s.takeoff_at_s = None
    elif s.takeoff_at_s is None:
        s.takeoff_at_s = now
    arm_us = ctx.time_usec(s.armed_at_s) if s.armed else 0
    takeoff_us = ctx.time_usec(s.takeoff_at_s) if s.takeoff_at_s is not None else 0
    return M.MAVLink_flight_information_message(ctx.time_boot_ms(now), arm_us, takeoff_us, 0)


def extended_sys_state(ctx, channel, now):
    return M.MAVLink_extended_sys_state_message(M.MAV_VTOL_STATE_UNDEFINED, int(ctx.state.landed))


BASE_PRODUCERS: dict[int, Producer] = {
    M.MAVLINK_MSG_ID_HEARTBEAT: heartbeat,
    M.MAVLINK_MSG_ID_SYS_STATUS: sys_status,
    M.MAVLINK_MSG_ID_POWER_STATUS: power_status,
    M.MAVLINK_MSG_ID_MEMINFO: meminfo,
    M.MAVLINK_MSG_ID_GPS_RAW_INT: gps_raw_int,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: global_position_int,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: local_position_ned,
    M.MAVLINK_MSG_ID_ATTITUDE: attitude,
    M.MAVLINK_MSG_ID_AHRS2: ahrs2,
    M.MAVLINK_MSG_ID_SIMSTATE: simstate,
    M.MAVLINK_MSG_ID_VFR_HUD: vfr_hud,
    M.MAVLINK_MSG_ID_SYSTEM_TIME: system_time,
    M.MAVLINK_MSG_ID_BATTERY_STATUS: battery_status,
    M.MAVLINK_MSG_ID_RAW_IMU: raw_imu,
    M.MAVLINK_MSG_ID_SCALED_IMU2: scaled_imu2,
    M.MAVLINK_MSG_ID_SCALED_PRESSURE: scaled_pressure,
    M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: servo_output_raw,
    M.MAVLINK_MSG_ID_RC_CHANNELS: rc_channels,
    M.MAVLINK_MSG_ID_RC_CHANNELS_RAW: rc_channels_raw,
    M.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT: nav_controller_output,
    M.MAVLINK_MSG_ID_MISSION_CURRENT: mission_current,
    M.MAVLINK_MSG_ID_AHRS: ahrs,
    M.MAVLINK_MSG_ID_WIND: wind,
    M.MAVLINK_MSG_ID_EKF_STATUS_REPORT: ekf_status_report,
    M.MAVLINK_MSG_ID_VIBRATION: vibration,
    M.MAVLINK_MSG_ID_HOME_POSITION: home_position,
    M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: gps_global_origin,
    M.MAVLINK_MSG_ID_AUTOPILOT_VERSION: autopilot_version,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: extended_sys_state,
    M.MAVLINK_MSG_ID_FLIGHT_INFORMATION: flight_information,
}
