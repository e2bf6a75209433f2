"""The payload's configuration keys: vehicle.camera, vehicle.gimbal and can.buses, off by default,
each problem reported as FILE:LINE: key.path: what is wrong."""

from __future__ import annotations

import pytest

from gcsd.config import ConfigError, default_config, parse_config
from gcsd.config.can import CanBusConfig


def problems(text: str) -> list[str]:
    with pytest.raises(ConfigError) as err:
        parse_config(text, "gcsd.yaml")
    return err.value.problems


def test_the_defaults_carry_nothing():
    c = default_config()
    assert (c.vehicle.camera, c.vehicle.gimbal, c.can.buses) == (False, False, ())


def test_buses_are_read_in_order_with_their_nodes():
    c = parse_config("vehicle: {camera: true, gimbal: true}\ncan:\n  buses:\n"
                     "    - {interface: virtual, channel: sim0, nodes: [gps, battery]}\n"
                     "    - {interface: socketcan, channel: can0, fd: true}\n")
    assert c.vehicle.camera and c.vehicle.gimbal
    assert c.can.buses == (CanBusConfig("virtual", "sim0", ("gps", "battery")),
                           CanBusConfig("socketcan", "can0", (), True))


def test_each_problem_names_its_line_and_key():
    text = ("vehicle: {camera: maybe}\n"
            "can:\n"
            "  buses:\n"
            "    - {interface: slcan, channel: x}\n"
            "    - {interface: socketcan, channel: can0, nodes: [gps]}\n"
            "    - {interface: virtual, channel: s, nodes: [gps, gps, radar]}\n"
            "    - {interface: virtual, channel: s}\n"
            "  colour: red\n")
    found = problems(text)
    assert any(p.startswith("gcsd.yaml:1: vehicle.camera:") for p in found), found
    assert any(p.startswith("gcsd.yaml:4: can.buses[0].interface:") for p in found), found
    assert "gcsd.yaml:5: can.buses[1].nodes: simulated nodes live on a virtual bus only" in found
    assert "gcsd.yaml:6: can.buses[2].nodes[1]: node 'gps' twice on one bus" in found
    assert any(p.startswith("gcsd.yaml:6: can.buses[2].nodes[2]:") for p in found), found
    assert "gcsd.yaml:7: can.buses[3].channel: virtual channel 's' is already a bus" in found
    assert any(p.startswith("gcsd.yaml:8: can.colour: unknown key") for p in found), found


def test_at_most_eight_buses():
    buses = "".join(f"    - {{interface: virtual, channel: b{n}}}\n" for n in range(9))
    assert any("at most 8 buses" in p for p in problems("can:\n  buses:\n" + buses))
