"""docs/commands.md documents every command the gimbal, the camera and CAN over MAVLink answer (the
tables are read from the services themselves, so a new command cannot go undocumented)."""

from __future__ import annotations

import re
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.payloads.camera.service import CameraService
from gcsd.payloads.can.service import CanService
from gcsd.payloads.gimbal.service import GimbalService

DOC = Path(__file__).resolve().parents[2] / "docs" / "commands.md"
NAMES = {v: k for k, v in vars(M).items() if k.startswith("MAV_CMD_") and isinstance(v, int)}


def _section() -> str:
    text = DOC.read_text()
    return text.split("## With a camera, a gimbal or CAN buses", 1)[1].split("\n## ", 1)[0]


def _commands(service_cls, method: str) -> set[int]:
    service = service_cls.__new__(service_cls)  # the tables only: no vehicle needed
    service.camera = None
    return set(getattr(service, method)())


def test_every_payload_command_has_a_row():
    documented = set(re.findall(r"MAV_CMD_\w+", _section()))
    tables = (_commands(GimbalService, "commands") | _commands(CanService, "commands")
              | _commands(CameraService, "commands") | _commands(CameraService, "camera_commands"))
    missing = sorted(NAMES[c] for c in tables if NAMES[c] not in documented)
    assert missing == [], f"not in docs/commands.md: {missing}"
