"""MAVProxy and MAVSDK, unmodified, through a companion gcsd with filters, a rate cap and a group.

The flight controller is a gcsd copter (sysid 1) with one UDP port. Between it and the companion
sits `TwoLinkRelay`, a radio and an LTE modem on the same flight-controller port: every datagram
from the flight controller goes out on both links, byte for byte; whatever the companion sends
on either link reaches the flight controller. The companion (type companion, sysid 1, compid
191) has both links as udp-client channels of group `fc`, and serves ground stations on `gcs`,
a channel with an in filter, an out filter and a rate cap. Each client then does what its users
do first, and goes on working when the radio link dies.
"""

from __future__ import annotations

import re
import select
import socket
import threading
import time

import pytest

from .conftest import mavproxy_for_params
from .test_bridge_interop import read_fc

pytestmark = pytest.mark.interop

GCS_CHANNEL = {"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0",
               "filter": {"in": {"block_src_sys": [77]}, "out": {"block_msgids": ["SERVO_OUTPUT_RAW"]}},
               "rate_limits": {"ATTITUDE": 2}}


class TwoLinkRelay:
    """Radio and LTE to one flight-controller UDP port; `kill("radio")` cuts a link both ways."""

    def __init__(self, fc_port: int) -> None:
        self.fc = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.fc.connect(("127.0.0.1", fc_port))
        self.links = {name: socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for name in ("radio", "lte")}
        for sock in self.links.values():
            sock.bind(("127.0.0.1", 0))
        self.companion: dict[str, tuple[str, int]] = {}  # link -> the companion's address on it
        self.dead: set[str] = set()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._relay, name="two-link-relay", daemon=True)
        self._thread.start()

    def port(self, link: str) -> int:
        return self.links[link].getsockname()[1]

    def kill(self, link: str) -> None:
        self.dead.add(link)

    def _relay(self) -> None:
        by_fd = {sock.fileno(): name for name, sock in self.links.items()}
        while not self._stop.is_set():
            ready, _, _ = select.select([self.fc, *self.links.values()], [], [], 0.05)
            for sock in ready:
                try:
                    data, addr = sock.recvfrom(65536)
                except OSError:
                    continue
                if sock is self.fc:
                    for name, where in list(self.companion.items()):
                        if name not in self.dead:
                            self.links[name].sendto(data, where)
                    continue
                name = by_fd[sock.fileno()]
                if name in self.dead:
                    continue
                self.companion[name] = addr
                try:
                    self.fc.send(data)
                except OSError:
                    pass

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        for sock in (self.fc, *self.links.values()):
            sock.close()


@pytest.fixture
def companion(daemon, tmp_path):
    fc = daemon({"state_dir": str(tmp_path / "fc"), "channels": [
        {"name": "telem", "type": "udp-server", "address": "127.0.0.1:0"}]})
    relay = TwoLinkRelay(fc.port("telem"))
    hub = daemon({"state_dir": str(tmp_path / "companion"), "vehicle": {"type": "companion", "sysid": 1},
                  "channels": [
                      {"name": "radio", "type": "udp-client", "address": f"127.0.0.1:{relay.port('radio')}",
                       "group": "fc"},
                      {"name": "lte", "type": "udp-client", "address": f"localhost:{relay.port('lte')}",
                       "group": "fc"},
                      GCS_CHANNEL]})
    yield hub, relay
    relay.close()


def _duplicates(hub) -> int:
    return sum(c["duplicates"] for c in hub.status()["channels"])


def _gates_worked(hub, timeout_s: float = 5.0) -> bool:
    """The gcs channel's out filter and rate cap have held frames back (the flight controller's
    SERVO_OUTPUT_RAW and its ATTITUDE above 2 Hz)."""
    deadline = time.monotonic() + timeout_s
    while True:
        gcs = next(c for c in hub.status()["channels"] if c["name"] == "gcs")
        if gcs["rate_limited"] > 0 and gcs["filtered_out"] > 0:
            return True
        if time.monotonic() > deadline:
            return False
        time.sleep(0.1)


async def test_mavsdk_arms_and_disarms_through_a_companion_with_filters_and_a_group(companion):
    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
    from mavsdk.asyncio.plugins.action import ActionAsync
    from mavsdk.asyncio.plugins.telemetry import FixType, TelemetryAsync

    from .test_mavsdk import TELEMETRY_WAIT_S, _first

    hub, relay = companion
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    try:
        await mavsdk.add_any_connection(f"udpout://127.0.0.1:{hub.port('gcs')}")
        system = await mavsdk.first_autopilot(timeout_s=10.0)
        assert system is not None, "MAVSDK found no autopilot through the companion"
        telemetry, action = TelemetryAsync(system), ActionAsync(system)
        try:
            await _first(telemetry.subscribe_gps_info(), lambda g: g.fix_type >= FixType.FIX_3D, TELEMETRY_WAIT_S,
                         "3D fix", telemetry.gps_info)
            await action.arm()
            await _first(telemetry.subscribe_armed(), lambda a: a is True, TELEMETRY_WAIT_S, "armed = True")
            assert _duplicates(hub) > 0  # both links carried the flight controller's frames
            relay.kill("radio")
            await action.disarm()
            await _first(telemetry.subscribe_armed(), lambda a: a is False, TELEMETRY_WAIT_S, "armed = False")
            assert _gates_worked(hub)
        finally:
            telemetry.destroy()
            action.destroy()
    finally:
        mavsdk.destroy()


def test_mavproxy_fetches_and_sets_parameters_through_a_companion_with_filters_and_a_group(companion, spawn,
                                                                                           tmp_path):
    hub, relay = companion
    mavproxy = mavproxy_for_params(spawn, hub.port("gcs"), tmp_path)
    mark = len(mavproxy.output)
    mavproxy.send_line("param fetch")
    got = mavproxy.output.wait_for(re.compile(r"Received (\d{3,}) parameters"), 30.0, since=mark)
    assert got is not None, f"the flight controller's parameters\n{mavproxy.describe()}"
    assert _duplicates(hub) > 0 and _gates_worked(hub)
    relay.kill("radio")
    mavproxy.send_line("param set RC8_TRIM 1466")
    deadline = time.monotonic() + 10
    value = None
    while time.monotonic() < deadline and value != 1466.0:  # asked of the flight controller itself
        msg = read_fc(hub.port("gcs"), "RC8_TRIM", 1.0)
        value = msg.param_value if msg else None
    assert value == 1466.0, f"the set went through the surviving link ({value})\n{mavproxy.describe()}"
    mavproxy.stop(5.0, end_of_input_first=True)
