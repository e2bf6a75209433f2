"""Telemetry: what each message contains (producers), read through a narrow view of the vehicle.

`producers()` returns a fresh table, message id -> producer(view, channel, now): the generic
ArduPilot messages (producers.py), the vehicle layer's (vehicle.py) and the gimbal's
(gimbal/telemetry.py). The composition root
hands it to each vehicle; nothing mutates a module-level table, so a test or an embedding
program can pass its own.
"""

from __future__ import annotations

from ..gimbal.telemetry import GIMBAL_PRODUCERS
from .producers import BASE_PRODUCERS, Producer
from .vehicle import VEHICLE_PRODUCERS
from .view import TelemetryView


def producers() -> dict[int, Producer]:
    return {**BASE_PRODUCERS, **VEHICLE_PRODUCERS, **GIMBAL_PRODUCERS}


__all__ = ["BASE_PRODUCERS", "VEHICLE_PRODUCERS", "Producer", "TelemetryView", "producers"]
