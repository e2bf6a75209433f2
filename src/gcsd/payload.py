"""What a vehicle carries (SPEC.md "Camera, gimbal and CAN"), wired onto a vehicle node.

`payload_params(defs, config)`: the parameter definitions with the MNT1_ group when
`vehicle.gimbal` is on (before the store is built, so a saved MNT1_ value loads).
`attach_payload(node, config)`: with `vehicle.gimbal`, the gimbal manager (gimbal/service.py) on
the autopilot component, taking the autopilot's ROI; with `vehicle.camera`, the camera component
(compid 100, camera/service.py) with its own command table, the autopilot's camera commands and
the mission's camera items; with `can.buses` (the first vehicle only: one owner per bus), CAN over
MAVLink (can/service.py). With all three off (the default) nothing is added and the commands keep
their "no such device" answers (services/peripherals.py).
"""

from __future__ import annotations

from pathlib import Path

from .camera.service import CAMERA_COMPID, CameraService
from .gimbal.params import with_mount_params
from .gimbal.service import GimbalService


def payload_params(defs: list, config) -> list:
    return with_mount_params(defs) if config.vehicle.gimbal else defs


def attach_payload(node, config) -> None:
    now = node.clock.now()
    if config.vehicle.gimbal:
        gimbal = GimbalService(node, now, previous_position_handler=node.handlers.get("GLOBAL_POSITION_INT"))
        node.gimbal = gimbal
        node.sim.mount_roi = gimbal.roi
        node.add_service(gimbal)
    if config.vehicle.camera:
        ftp_root = Path(node.state_dir) / config.ftp.root if node.state_dir is not None else None
        camera = CameraService(node, ftp_root, now)
        node.camera = camera
        node.add_service(camera)
        node.commands.add_component(CAMERA_COMPID, camera.camera_commands())
        node.sim.payload_items.update(camera.mission_items())
