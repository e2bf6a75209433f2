"""Telemetry producers of the gimbal manager (registered in gcsd.telemetry.PRODUCERS).

GIMBAL_MANAGER_INFORMATION (on MAV_CMD_REQUEST_MESSAGE), GIMBAL_MANAGER_STATUS and
GIMBAL_DEVICE_ATTITUDE_STATUS (at the rate SET_MESSAGE_INTERVAL asks, as ArduPilot), from the
vehicle's gimbal service, stepped to `now` first. A vehicle without a gimbal says nothing (None),
as ArduPilot with no mount.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as M


def _mount(node, now):
    service = getattr(node, "gimbal", None)
    return None if service is None else service.sync(now)


def gimbal_manager_information(node, channel, now):
    mount = _mount(node, now)
    return None if mount is None else mount.information(node.time_boot_ms(now))


def gimbal_manager_status(node, channel, now):
    mount = _mount(node, now)
    return None if mount is None else mount.status(node.time_boot_ms(now))


def gimbal_device_attitude_status(node, channel, now):
    mount = _mount(node, now)
    return None if mount is None else mount.attitude_status(node.time_boot_ms(now))


GIMBAL_PRODUCERS = {
    M.MAVLINK_MSG_ID_GIMBAL_MANAGER_INFORMATION: gimbal_manager_information,
    M.MAVLINK_MSG_ID_GIMBAL_MANAGER_STATUS: gimbal_manager_status,
    M.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS: gimbal_device_attitude_status,
}
