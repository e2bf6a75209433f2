"""A companion-computer bridge on one machine, for the bridge tests.

A flight controller (a gcsd copter, sysid 1 compid 1) and a companion computer (a gcsd of type
companion, sysid 1 compid 191) are joined by a serial line: two PTY pairs whose master ends a
relay thread connects, byte for byte, as a null-modem cable would. The companion also has two
UDP server channels for ground stations. Everything the ground stations ask of the flight
controller goes through the companion's router.
"""

from __future__ import annotations

import os
import select
import threading


class NullModem:
    """Two PTYs joined at their master ends; `devices` are the slave paths to open as serial."""

    def __init__(self) -> None:
        self._ends = [os.openpty(), os.openpty()]
        self.devices = [os.ttyname(slave) for _, slave in self._ends]
        self.bytes = [0, 0]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._relay, name="null-modem", daemon=True)
        self._thread.start()

    def _relay(self) -> None:
        a, b = self._ends[0][0], self._ends[1][0]
        peer = {a: b, b: a}
        index = {a: 0, b: 1}
        while not self._stop.is_set():
            ready, _, _ = select.select([a, b], [], [], 0.05)
            for fd in ready:
                try:
                    data = os.read(fd, 65536)
                    os.write(peer[fd], data)
                    self.bytes[index[fd]] += len(data)
                except OSError:  # a side not open yet, or closed
                    pass

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        for master, slave in self._ends:
            os.close(master)
            os.close(slave)


def bridge_configs(tmp_path, modem: NullModem) -> tuple[dict, dict]:
    flight_controller = {
        "state_dir": str(tmp_path / "fc"),
        "vehicle": {"type": "copter", "sysid": 1},
        "channels": [{"name": "telem1", "type": "serial", "device": modem.devices[0], "baud": 921600}],
    }
    companion = {
        "state_dir": str(tmp_path / "companion"),
        "vehicle": {"type": "companion", "sysid": 1},
        "channels": [
            {"name": "fc", "type": "serial", "device": modem.devices[1], "baud": 921600},
            {"name": "gcs1", "type": "udp-server", "address": "127.0.0.1:0"},
            {"name": "gcs2", "type": "udp-server", "address": "127.0.0.1:0"},
        ],
    }
    return flight_controller, companion
