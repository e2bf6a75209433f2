"""What a vehicle carries (SPEC.md "Camera, gimbal and CAN"), built for the composition root.

- `payload_params(defs, config)`: the parameter definitions with the MNT1_ group when
  `vehicle.gimbal` is on (before the store is built, so a saved MNT1_ value loads).
- `gimbal_service(node, w)`: with `vehicle.gimbal`, the gimbal manager on the autopilot
  component; it takes the autopilot's ROI (`Autopilot.mount_roi`; not an antenna tracker's, which
  points itself at it), and its producers join the
  vehicle's table (GIMBAL_MANAGER_*, GIMBAL_DEVICE_ATTITUDE_STATUS).
- `camera_service(node, w)`: with `vehicle.camera`, the camera component (compid 100) on the
  gimbal when there is one; the autopilot's camera commands; the mission's camera items
  (`Autopilot.payload_items`).
- `can_service(node, w)`: with `can.buses`, CAN over MAVLink, for the first vehicle only (one
  owner per bus, even in a swarm).
Each returns None when its switch is off (the default): the commands then keep their "no such
device" answers (services/peripherals.py), and compose.OVERRIDES says who wins when it is on.
"""

from __future__ import annotations

from gcsd.payloads.gimbal.params import with_mount_params
from gcsd.payloads.gimbal.service import GimbalService
from gcsd.payloads.gimbal.telemetry import gimbal_producers
from gcsd.vehicle.autopilot.settings import Behaviour

EXTRA3 = "extra3"  # the stream GIMBAL_DEVICE_ATTITUDE_STATUS is in (streams.py)


def payload_params(defs: list, config) -> list:
    return with_mount_params(defs) if config.vehicle.gimbal else defs


def gimbal_service(node, w):
    if not w.config.vehicle.gimbal:
        return None
    now = node.now()
    service = GimbalService(node, now)
    if Behaviour.TRACK not in set(node.vehicle.behaviours.values()):  # an antenna tracker points itself at the ROI
        node.autopilot.mount_roi = service.roi
    node.producers.update(gimbal_producers(service))
    for link in node.links:  # the streams were set before this producer existed: EXTRA3 again, with it
        link.set_stream_rate(EXTRA3, link.stream_rates[EXTRA3], now)
    return service


def camera_service(node, w):
    if not w.config.vehicle.camera:
        return None
    # Pillow (JPEG and EXIF) is loaded only when a camera is configured
    from gcsd.payloads.camera.service import CameraService
    service = CameraService(node, node.state_dir / w.config.ftp.root, node.now(), w.services.get("gimbal"))
    node.autopilot.payload_items.update(service.mission_items())
    return service


def can_service(node, w):
    if not w.config.can.buses or node.index != 0:
        return None
    from gcsd.payloads.can.service import (
        CanService,  # python-can and dronecan: loaded only when a bus is configured
    )
    return CanService(node, w.config.can)
