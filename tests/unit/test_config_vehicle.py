"""Configuration keys of the vehicle layer: serial_control entries and the high_latency option."""

from __future__ import annotations

from pathlib import Path

import pytest

from gcsd.config import ConfigError, SerialControlPort, default_config, load_config, parse_config

REPO = Path(__file__).resolve().parents[2]


def test_serial_control_maps_ports_to_devices_with_a_default_baud():
    c = parse_config("serial_control:\n  - {port: gps1, device: /dev/ttyUSB1}\n  - {port: serial3, device: /dev/x, baud: 9600}\n")
    assert c.serial_control == (SerialControlPort("gps1", "/dev/ttyUSB1", 115200), SerialControlPort("serial3", "/dev/x", 9600))


@pytest.mark.parametrize("text, problem", [
    ("serial_control:\n  - {port: gps7, device: /dev/x}\n", "serial_control[0].port: expected telem1|"),
    ("serial_control:\n  - {port: gps1}\n", "serial_control[0].device: required"),
    ("serial_control:\n  - {port: gps1, device: /a}\n  - {port: gps1, device: /b}\n", "duplicate serial_control port 'gps1'"),
    ("serial_control:\n  - {port: gps1, device: /a, baud: 0}\n", "serial_control[0].baud: expected an integer >= 1"),
    ("serial_control:\n  - {port: gps1, device: /a, speed: 9}\n", "serial_control[0].speed: unknown key"),
])
def test_bad_serial_control_entries_are_reported_by_line_and_key(text, problem):
    with pytest.raises(ConfigError) as err:
        parse_config(text, "c.yaml")
    assert any(problem in p for p in err.value.problems), err.value.problems


def test_high_latency_is_a_channel_option():
    c = parse_config("channels:\n  - {name: sat, type: udp-server, address: '127.0.0.1:0', options: [high_latency]}\n")
    assert c.channels[0].options == frozenset({"high_latency"})


def test_the_documented_default_file_is_still_the_built_in_default():
    assert load_config(REPO / "config" / "gcsd.yaml") == default_config()
