"""Telemetry producers of the vehicle layer, merged into the table by gcsd.vehicle.telemetry.producers().

- HIGH_LATENCY2 (REFERENCE.md section 11): position, altitudes, headings in deg/2, target
  distance in dam, speeds in m/s x 5 (capped 255), wind, battery, the current mission item,
  HL_FAILURE bits for what is unhealthy (GPS without a fix, a battery failsafe, a fence
  breach, a lost GCS), custom0 = base_mode.
- POSITION_TARGET_GLOBAL_INT: what the navigation controller aims at (nothing without a target).
- FENCE_STATUS: breach status, count, type and time (nothing while the fence is disabled).
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.sim.geo import deg_e7

AIR_TEMPERATURE_C = 20
TARGET_TYPE_MASK = 0b110111111000  # position only



def _clamp(v: float, lo: int, hi: int) -> int:
    return int(max(lo, min(hi, v)))


def high_latency2(ctx, channel, now):
    s = ctx.state
    v = ctx.vehicle
    target = s.target
    failures = 0
    if s.gps_fix_type < 3:
        failures |= M.HL_FAILURE_FLAG_GPS
    if s.failsafe == "Battery":
        failures |= M.HL_FAILURE_FLAG_BATTERY
    if s.failsafe == "Fence":
        failures |= M.HL_FAILURE_FLAG_GEOFENCE
    if s.failsafe == "GCS":
        failures |= M.HL_FAILURE_FLAG_OFFBOARD_LINK
    wind = math.hypot(s.wind_n_ms, s.wind_e_ms)
    wind_from = (math.degrees(math.atan2(s.wind_e_ms, s.wind_n_ms)) + 180.0) % 360.0
    return M.MAVLink_high_latency2_message(
        ctx.time_boot_ms(now), v.mav_type, M.MAV_AUTOPILOT_ARDUPILOTMEGA, s.mode & 0xFFFF,
        deg_e7(s.lat), deg_e7(s.lon), _clamp(s.alt_amsl_m, -32768, 32767),
        _clamp(target[2] if target else s.alt_amsl_m, -32768, 32767),
        _clamp(s.heading_deg / 2, 0, 179), _clamp(s.target_bearing_deg / 2, 0, 179),
        _clamp(s.wp_dist_m / 10, 0, 65535), _clamp(s.throttle_pct, 0, 100),
        _clamp(s.airspeed_ms * 5, 0, 255), _clamp(ctx.autopilot.speed_ms * 5, 0, 255), _clamp(s.groundspeed_ms * 5, 0, 255),
        _clamp(wind * 5, 0, 255), _clamp(wind_from / 2, 0, 179), 0, 0, AIR_TEMPERATURE_C, 0,
        s.battery_remaining_pct, ctx.plans.mission.current_seq, failures, v.base_mode(s), 0, 0,
    )


def position_target_global_int(ctx, channel, now):
    s = ctx.state
    if s.target is None:
        return None
    lat, lon, alt = s.target
    return M.MAVLink_position_target_global_int_message(
        ctx.time_boot_ms(now), M.MAV_FRAME_GLOBAL_INT, TARGET_TYPE_MASK, deg_e7(lat), deg_e7(lon), alt,
        0, 0, 0, 0, 0, 0, 0, 0,
    )


def fence_status(ctx, channel, now):
    params = ctx.params
    if "FENCE_ENABLE" not in params or not params.get("FENCE_ENABLE"):
        return None
    s = ctx.state
    breached = int(bool(ctx.autopilot.failsafes.fence_breached))
    return M.MAVLink_fence_status_message(breached, s.fence_breach_count, s.fence_breach_type,
                                          s.fence_breach_time_ms & 0xFFFFFFFF, 0)


VEHICLE_PRODUCERS = {
    M.MAVLINK_MSG_ID_HIGH_LATENCY2: high_latency2,
    M.MAVLINK_MSG_ID_POSITION_TARGET_GLOBAL_INT: position_target_global_int,
    M.MAVLINK_MSG_ID_FENCE_STATUS: fence_status,
}
