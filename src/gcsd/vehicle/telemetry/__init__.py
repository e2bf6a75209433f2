"""Telemetry: what each message contains (producers), read through a narrow view of the vehicle.

`producers()` returns a fresh table, message id -> producer(view, channel, now): the generic
ArduPilot messages (producers.py) and the vehicle layer's (vehicle.py). The composition root
hands it to each vehicle (adding a gimbal's, gimbal/telemetry.py, to a vehicle that has one);
nothing mutates a module-level table, so a test or an embedding program can pass its own.
"""

from __future__ import annotations

from gcsd.vehicle.telemetry.producers import BASE_PRODUCERS, Producer
from gcsd.vehicle.telemetry.vehicle import VEHICLE_PRODUCERS
from gcsd.vehicle.telemetry.view import TelemetryView


def producers() -> dict[int, Producer]:
    return {**BASE_PRODUCERS, **VEHICLE_PRODUCERS}


__all__ = ["BASE_PRODUCERS", "VEHICLE_PRODUCERS", "Producer", "TelemetryView", "producers"]
