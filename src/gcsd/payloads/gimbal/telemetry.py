"""Telemetry producers of a vehicle's gimbal manager, bound to its gimbal service.

GIMBAL_MANAGER_INFORMATION (on MAV_CMD_REQUEST_MESSAGE), GIMBAL_MANAGER_STATUS and
GIMBAL_DEVICE_ATTITUDE_STATUS (at the rate SET_MESSAGE_INTERVAL asks, and in EXTRA3, as
ArduPilot), from the gimbal service, stepped to `now` first. The composition root adds them to
the producer table of a vehicle that has a gimbal; a vehicle without one has no producer for
these ids (so its EXTRA3 stream skips GIMBAL_DEVICE_ATTITUDE_STATUS).
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as M


def gimbal_producers(service) -> dict:
    """msgid -> producer(view, channel, now) for the vehicle whose gimbal service this is."""

    def information(view, channel, now):
        return service.sync(now).information(view.time_boot_ms(now))

    def status(view, channel, now):
        return service.sync(now).status(view.time_boot_ms(now))

    def attitude(view, channel, now):
        return service.sync(now).attitude_status(view.time_boot_ms(now))

    return {
        M.MAVLINK_MSG_ID_GIMBAL_MANAGER_INFORMATION: information,
        M.MAVLINK_MSG_ID_GIMBAL_MANAGER_STATUS: status,
        M.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS: attitude,
    }
