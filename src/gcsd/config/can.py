"""The `can` section (SPEC.md "Camera, gimbal and CAN"), read by config.py's reader.

    can:
      buses:                      # CAN over MAVLink: bus n (0-based) is the n-th entry
        - interface: virtual      # virtual | socketcan (python-can interfaces)
          channel: sim0           # the python-can channel: a virtual bus's name, or can0, vcan0...
          nodes: [gps, battery]   # virtual only: simulated DroneCAN nodes on it (dronecan package)
          fd: false               # CAN FD frames (CANFD_FRAME) on this bus

Checks: at most MAX_BUSES buses (CAN_FRAME.bus is a uint8, ArduPilot has 3 at most: gcsd keeps 8);
two buses may not share an (interface, channel); nodes only on a virtual bus, each kind once per
bus. This module imports no CAN library: validating a file does not need one.
"""

from __future__ import annotations

from dataclasses import dataclass

CAN_KEYS = ("buses",)
BUS_KEYS = ("interface", "channel", "nodes", "fd")
INTERFACES = ("virtual", "socketcan")
NODE_KINDS = ("gps", "battery")
MAX_BUSES = 8


@dataclass(frozen=True)
class CanBusConfig:
    interface: str = "virtual"
    channel: str = "sim0"
    nodes: tuple[str, ...] = ()
    fd: bool = False


@dataclass(frozen=True)
class CanConfig:
    buses: tuple[CanBusConfig, ...] = ()


def read_can(r, f) -> CanConfig:
    s = r.section(f, CAN_KEYS)
    buses: list[CanBusConfig] = []
    seen: set[tuple[str, str]] = set()
    items = r.sequence(s["buses"])
    if len(items) > MAX_BUSES:
        r.problem(s["buses"], f"at most {MAX_BUSES} buses")
    for item in items[:MAX_BUSES]:
        b = r.section(item, BUS_KEYS)
        interface = r.choice(b["interface"], "virtual", INTERFACES)
        channel = r.text(b["channel"], "sim0")
        if (interface, channel) in seen:
            r.problem(b["channel"], f"{interface} channel {channel!r} is already a bus")
        seen.add((interface, channel))
        nodes: list[str] = []
        for n in r.sequence(b["nodes"]):
            kind = r.choice(n, "", NODE_KINDS)
            if kind and kind in nodes:
                r.problem(n, f"node {kind!r} twice on one bus")
            elif kind:
                nodes.append(kind)
        if nodes and interface != "virtual":
            r.problem(b["nodes"], "simulated nodes live on a virtual bus only")
            nodes = []
        buses.append(CanBusConfig(interface, channel, tuple(nodes), r.boolean(b["fd"], False)))
    return CanConfig(tuple(buses))
