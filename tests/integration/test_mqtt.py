"""Fleet scale on a real Mosquitto (SPEC.md "Fleet scale"): gcsd instances meet on a broker.

Every test starts Debian's mosquitto on a free loopback port (mosquitto.py) and real gcsd
daemons whose `mqtt` channels connect to it; a pymavlink ground station talks UDP to the
ground-side gcsd, and a plain paho subscriber (`Tap`) records what crosses the broker, so the
topics and the bytes on them are checked directly.

1. Two vehicle-side daemons (swarms of 10 and 20) and one ground-side daemon: the ground station
   sees all 30, and a parameter set, a mission upload and an arming each reach one vehicle only.
2. A companion bridge: a flight controller on a PTY serial line behind a companion whose mqtt
   channel is vehicle-side; the ground station reads and sets the flight controller's parameters.
3. The broker killed and restarted: both sides reconnect, telemetry resumes, no daemon stops.
4. Signing end to end: frames signed by the ground station are verified by the vehicle, the
   vehicle's signed frames reach the ground station byte-exact (the same bytes as on the broker).
5. mqtts:// with a CA file and username + password_file against a TLS, password-only broker; a
   wrong password is refused (the channel's open fails, so run_channel retries).
6. Two ground sides split one fleet by `sysids`; 7. `no_forward` on an mqtt channel is honoured.
8. Garbage, truncated, oversized and spoofed-source messages on the broker are counted and dropped.
"""

from __future__ import annotations

import asyncio
import hashlib
import os
import shutil
import threading
import time

import paho.mqtt.client as paho
import pytest
import yaml
from paho.mqtt.enums import CallbackAPIVersion

from gcsd.config import parse_config
from gcsd.links.channel import Channel
from gcsd.links.mqtt import MqttLink
from gcsd.vehicle.mission import MissionItem

from .bridge import NullModem
from .helpers import Client, M, pump, pump_until, udp_channel, udp_url, wait_for
from .mission_client import MissionClient
from .mosquitto import Mosquitto, mosquitto_binary, password_file, tls_files

GROUND_SYSID = 250  # the ground-side daemon's own component (a companion), outside the fleet's sysids


@pytest.fixture
def broker(tmp_path):
    if mosquitto_binary() is None:
        if os.environ.get("CI"):
            pytest.fail("mosquitto is missing: .ci/run installs it")
        pytest.skip("mosquitto is not installed (apt-get install mosquitto)")
    b = Mosquitto(tmp_path / "broker").start()
    yield b
    b.stop()


def mqtt_channel(broker: Mosquitto, role: str, topic: str, **extra) -> dict:
    return {"name": "fleet", "type": "mqtt", "broker": broker.url, "topic": topic, "role": role, **extra}


def vehicle_side(tmp_path, name: str, broker: Mosquitto, topic: str, **vehicle) -> dict:
    return {"state_dir": str(tmp_path / name), "vehicle": vehicle,
            "channels": [mqtt_channel(broker, "vehicle", topic)]}


def ground_side(tmp_path, broker: Mosquitto, topic: str, **mqtt_extra) -> dict:
    return {"state_dir": str(tmp_path / "ground"), "vehicle": {"type": "companion", "sysid": GROUND_SYSID},
            "channels": [udp_channel("gcs"), mqtt_channel(broker, "ground", topic, **mqtt_extra)]}


class Tap:
    """A paho subscriber recording (topic, payload) of every message under a topic filter."""

    def __init__(self, broker: Mosquitto, topic_filter: str) -> None:
        self.messages: list[tuple[str, bytes]] = []
        self._lock = threading.Lock()
        subscribed = threading.Event()
        self.client = paho.Client(CallbackAPIVersion.VERSION2)
        self.client.on_message = lambda c, u, m: self._add(m.topic, bytes(m.payload))
        self.client.on_subscribe = lambda *args: subscribed.set()
        self.client.on_connect = lambda c, *args: c.subscribe(topic_filter)
        self.client.connect("127.0.0.1", broker.port)
        self.client.loop_start()
        assert subscribed.wait(5), "the tap did not subscribe"

    def _add(self, topic: str, payload: bytes) -> None:
        with self._lock:
            self.messages.append((topic, payload))

    def mark(self) -> int:
        with self._lock:
            return len(self.messages)

    def since(self, mark: int) -> list[tuple[str, bytes]]:
        with self._lock:
            return self.messages[mark:]

    def has(self, item: tuple[str, bytes], mark: int, timeout: float = 3.0) -> bool:
        """Whether (topic, payload) arrives after `mark` within `timeout` (the tap's thread may
        deliver after the daemons did)."""
        end = time.monotonic() + timeout
        while item not in self.since(mark):
            if time.monotonic() > end:
                return False
            time.sleep(0.02)
        return True

    def publish(self, topic: str, payload: bytes) -> None:
        self.client.publish(topic, payload, 0).wait_for_publish(5)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()


@pytest.fixture
def tap(broker):
    made: list[Tap] = []

    def make(topic_filter: str) -> Tap:
        t = Tap(broker, topic_filter)
        made.append(t)
        return t

    yield make
    for t in made:
        t.close()


def heartbeats(gcs: Client, seconds: float) -> dict[tuple[int, int], list]:
    """Send a GCS HEARTBEAT each second for `seconds`; the HEARTBEATs heard, by source."""
    mark = gcs.mark()
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        gcs.heartbeat()
        pump([gcs], min(1.0, end - time.monotonic()))
    out: dict[tuple[int, int], list] = {}
    for r in gcs.since(mark, "HEARTBEAT"):
        out.setdefault(r.src, []).append(r.msg)
    return out


def heard_all(gcs: Client, wanted: set[tuple[int, int]], timeout: float = 10.0) -> dict[tuple[int, int], list]:
    """HEARTBEATs by source, from now until every source in `wanted` has sent one (a GCS HEARTBEAT
    each second meanwhile); returns early, or at `timeout` with whatever was heard."""
    mark = gcs.mark()
    end = time.monotonic() + timeout
    out: dict[tuple[int, int], list] = {}
    while time.monotonic() < end:
        gcs.heartbeat()
        pump([gcs], 0.25)
        for r in gcs.since(mark, "HEARTBEAT"):
            out.setdefault(r.src, []).append(r.msg)
        mark = gcs.mark()
        if wanted <= set(out):
            break
        pump([gcs], 0.75)
    return out


def param_value(gcs: Client, target: tuple[int, int], name: bytes) -> float | None:
    mark = gcs.mark()
    gcs.send(M.MAVLink_param_request_read_message(*target, name, -1))
    r = wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and r.src == target, 3.0, mark)
    return None if r is None else r.msg.param_value


def mission_count(gcs: Client, target: tuple[int, int]) -> int | None:
    mark = gcs.mark()
    gcs.send(M.MAVLink_mission_request_list_message(*target, 0))
    r = wait_for(gcs, lambda r: r.type == "MISSION_COUNT" and r.src == target, 3.0, mark)
    if r is not None:
        gcs.send(M.MAVLink_mission_ack_message(*target, M.MAV_MISSION_ACCEPTED, 0))
    return None if r is None else r.msg.count


REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
PLAN = [
    MissionItem(M.MAV_CMD_NAV_WAYPOINT, M.MAV_FRAME_GLOBAL, 1, 1, 0, 0, 0, 0, -353632620, 1491652370, 584.0),
    MissionItem(M.MAV_CMD_NAV_TAKEOFF, REL, 0, 1, 0, 0, 0, 0, 0, 0, 20.0),
    MissionItem(M.MAV_CMD_NAV_WAYPOINT, REL, 0, 1, 0, 2.0, 0, 0, -353622620, 1491659370, 30.0),
    MissionItem(M.MAV_CMD_NAV_RETURN_TO_LAUNCH, M.MAV_FRAME_MISSION, 0, 1, 0, 0, 0, 0, 0, 0, 0.0),
]


def test_two_vehicle_side_swarms_are_one_fleet_and_each_request_reaches_one_vehicle(broker, daemon, client,
                                                                                   tap, tmp_path):
    topic = "gcsd/fleet1"
    daemon(vehicle_side(tmp_path, "a", broker, topic, count=10, sysid=1))
    daemon(vehicle_side(tmp_path, "b", broker, topic, count=20, sysid=21))
    ground = daemon(ground_side(tmp_path, broker, topic))
    gcs = client(udp_url(ground.port("gcs")))
    fleet = set(range(1, 11)) | set(range(21, 41))

    seen = heard_all(gcs, {(s, 1) for s in fleet} | {(GROUND_SYSID, 191)})
    assert {s for s, c in seen if c == 1} == fleet, "all 30 vehicles of both processes are seen"
    assert (GROUND_SYSID, 191) in seen, "and the ground-side daemon's own component"

    # a parameter set on vehicle 4 (process a) changes vehicle 4 alone, and went down on down/4 only
    default = param_value(gcs, (3, 1), b"WPNAV_SPEED")
    assert default is not None and default != 777.0
    downlink = tap(f"{topic}/down/#")
    mark, tmark = gcs.mark(), downlink.mark()
    sent = gcs.send(M.MAVLink_param_set_message(4, 1, b"WPNAV_SPEED", 777.0, M.MAV_PARAM_TYPE_INT16))
    echo = wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == "WPNAV_SPEED", 3.0, mark)
    assert echo is not None and echo.src == (4, 1) and echo.msg.param_value == 777.0
    for sysid in (3, 5, 21, 40):
        assert param_value(gcs, (sysid, 1), b"WPNAV_SPEED") == default, f"vehicle {sysid} unchanged"
    assert param_value(gcs, (4, 1), b"WPNAV_SPEED") == 777.0
    assert downlink.has((f"{topic}/down/4", sent), tmark), "the set went down on vehicle 4's topic"
    assert [t for t, raw in downlink.since(tmark) if raw == sent] == [f"{topic}/down/4"], "and only there"

    # a mission uploaded to vehicle 30 (process b) lands there alone
    empty = mission_count(gcs, (29, 1))
    assert empty is not None and empty < len(PLAN)
    assert MissionClient(gcs, target=(30, 1)).upload(PLAN) == M.MAV_MISSION_ACCEPTED
    assert mission_count(gcs, (30, 1)) == len(PLAN)
    for sysid in (29, 31, 4):
        assert mission_count(gcs, (sysid, 1)) == empty, f"vehicle {sysid} has no mission"

    # vehicle 7 (process a) arms; in the same window every other vehicle reports disarmed
    mark = gcs.mark()
    gcs.command_long(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=(7, 1))
    ack = wait_for(gcs, lambda r: r.type == "COMMAND_ACK" and r.msg.command == M.MAV_CMD_COMPONENT_ARM_DISARM,
                   3.0, mark)
    assert ack is not None and ack.src == (7, 1) and ack.msg.result == M.MAV_RESULT_ACCEPTED
    seen = heard_all(gcs, {(s, 1) for s in fleet})  # every vehicle's state after the arming
    armed = {s for (s, c), msgs in seen.items() if c == 1 and msgs[-1].base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED}
    assert {s for s, c in seen if c == 1} == fleet
    assert armed == {7}


@pytest.fixture
def modem():
    """A null-modem PTY pair, closed after the daemons using it have stopped (set up before them)."""
    m = NullModem()
    yield m
    m.close()


def test_companion_bridge_reached_from_the_ground_side_through_the_broker(broker, modem, daemon, client, tmp_path):
    topic = "gcsd/bridge"
    daemon({"state_dir": str(tmp_path / "fc"), "vehicle": {"type": "copter", "sysid": 7},
            "channels": [{"name": "telem1", "type": "serial", "device": modem.devices[0], "baud": 921600}]})
    # the companion on its own sysid: it takes TOPIC/down/7 only because it learned the route to 7
    daemon({"state_dir": str(tmp_path / "companion"), "vehicle": {"type": "companion", "sysid": 70},
            "channels": [{"name": "fc", "type": "serial", "device": modem.devices[1], "baud": 921600},
                         mqtt_channel(broker, "vehicle", topic)]})
    ground = daemon(ground_side(tmp_path, broker, topic))
    gcs = client(udp_url(ground.port("gcs")))
    seen = heard_all(gcs, {(7, 1), (70, 191)})
    assert seen.get((7, 1)) and seen[(7, 1)][-1].type == M.MAV_TYPE_QUADROTOR, "the flight controller"
    assert seen.get((70, 191)) and seen[(70, 191)][-1].type == M.MAV_TYPE_ONBOARD_CONTROLLER, "the companion"

    assert param_value(gcs, (7, 1), b"SYSID_THISMAV") == 7.0
    mark = gcs.mark()
    gcs.send(M.MAVLink_param_set_message(7, 1, b"RC7_TRIM", 1555.0, M.MAV_PARAM_TYPE_INT16))
    r = wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == "RC7_TRIM", 3.0, mark)
    assert r is not None and r.src == (7, 1) and r.msg.param_value == 1555.0
    assert param_value(gcs, (7, 1), b"RC7_TRIM") == 1555.0
    saved = tmp_path / "fc" / "mav.parm"
    deadline = time.monotonic() + 5.0  # writes are batched, at most one file write per second
    while "RC7_TRIM" not in saved.read_text() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert "RC7_TRIM" in saved.read_text(), "saved by the flight controller"
    # the companion's own component answers for itself on the same path
    assert param_value(gcs, (70, 191), b"SYSID_THISMAV") == 70.0


def test_broker_killed_and_restarted_both_sides_reconnect_and_telemetry_resumes(broker, daemon, client,
                                                                                tmp_path):
    topic = "gcsd/restart"
    vehicles = daemon(vehicle_side(tmp_path, "v", broker, topic, count=3, sysid=1))
    ground = daemon(ground_side(tmp_path, broker, topic))
    gcs = client(udp_url(ground.port("gcs")))
    seen = heard_all(gcs, {(1, 1), (2, 1), (3, 1)})
    assert {1, 2, 3} <= {s for s, _ in seen}
    before = vehicles.stats("fleet")["packets_in"]

    broker.kill()
    deadline = time.monotonic() + 5.0  # both sides notice at once: the broker's sockets are reset
    while (ground.stats("fleet")["peers"] or vehicles.stats("fleet")["peers"]) and time.monotonic() < deadline:
        pump([gcs], 0.05)
    assert ground.stats("fleet")["peers"] == 0 and vehicles.stats("fleet")["peers"] == 0
    seen = heartbeats(gcs, 2.0)
    assert (GROUND_SYSID, 191) in seen, "the ground-side daemon still serves its UDP ground station"
    assert not {1, 2, 3} & {s for s, _ in seen}, "no vehicle telemetry without a broker"

    broker.start()  # same port
    back = {s for s, _ in heard_all(gcs, {(1, 1), (2, 1), (3, 1)}, timeout=15.0)} & {1, 2, 3}
    assert back == {1, 2, 3}, "vehicle telemetry resumed through the restarted broker"
    assert param_value(gcs, (2, 1), b"SYSID_THISMAV") == 2.0, "and requests reach the vehicles again"
    assert vehicles.stats("fleet")["packets_in"] > before, "the vehicle side hears the ground again"
    # (no daemon stopped: both answered after the restart; teardown's stop() re-raises any daemon error)


KEY = hashlib.sha256(b"fleet signing key").digest()


def test_signing_end_to_end_through_the_broker(broker, daemon, client, tap, tmp_path):
    topic = "gcsd/signed"
    signing = {"key": KEY.hex(), "require": True}
    vehicle = daemon({**vehicle_side(tmp_path, "v", broker, topic, sysid=3), "signing": signing})
    ground = daemon({**ground_side(tmp_path, broker, topic), "signing": {"key": KEY.hex()}})
    gcs = client(udp_url(ground.port("gcs")))
    gcs.mav.signing.secret_key = KEY
    gcs.mav.signing.link_id = 1
    gcs.mav.signing.timestamp = int((time.time() - 1420070400) * 100_000)
    gcs.mav.signing.sign_outgoing = True
    uplink, downlink = tap(f"{topic}/up/3/1"), tap(f"{topic}/down/#")
    assert (3, 1) in heard_all(gcs, {(3, 1)})

    mark, umark, dmark = gcs.mark(), uplink.mark(), downlink.mark()
    sent = gcs.send(M.MAVLink_param_request_read_message(3, 1, b"SYSID_THISMAV", -1))
    reply = wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and r.src == (3, 1), 3.0, mark)
    assert reply is not None and reply.msg.param_value == 3.0, "the vehicle verified the signed request"
    assert downlink.has((f"{topic}/down/3", sent), dmark), "the signed request crossed byte-exact"
    assert reply.raw[2] & 0x01, "the reply is signed"
    assert hashlib.sha256(KEY + reply.raw[:-6]).digest()[:6] == reply.raw[-6:]
    assert uplink.has((f"{topic}/up/3/1", reply.raw), umark), "and reached the ground station byte-exact"

    # an unsigned request in the same window: forwarded by the ground side, refused by the vehicle
    unsigned = client(udp_url(ground.port("gcs")), 254, 190)
    rejects = vehicle.stats("fleet").get("signature_rejects_unsigned", 0)
    mark = unsigned.mark()
    unsigned.send(M.MAVLink_param_request_read_message(3, 1, b"SYSID_THISMAV", -1))
    unsigned.heartbeat()
    # the refusal (ground side, broker, vehicle side) is awaited, in a window of at least 1.5 s in
    # which no answer reaches the unsigned station
    assert pump_until([unsigned, gcs], lambda: vehicle.stats("fleet").get("signature_rejects_unsigned", 0) > rejects,
                      at_least_s=1.5), "the unsigned request never reached the vehicle side"
    assert not [r for r in unsigned.since(mark, "PARAM_VALUE") if r.src == (3, 1)]
    assert param_value(gcs, (3, 1), b"SYSID_THISMAV") == 3.0, "the signed station is still answered"


@pytest.fixture
def tls_broker(tmp_path):
    if mosquitto_binary() is None or shutil.which("openssl") is None:
        if os.environ.get("CI"):
            pytest.fail("mosquitto or openssl is missing: .ci/run installs mosquitto")
        pytest.skip("mosquitto or openssl is not installed")
    files = tls_files(tmp_path / "tls")
    passwd = password_file(tmp_path / "tls" / "passwd", "fleet", "s3cret pass")
    b = Mosquitto(tmp_path / "tls-broker", anonymous=False,
                  extra=f"cafile {files['ca']}\ncertfile {files['cert']}\nkeyfile {files['key']}\n"
                        f"password_file {passwd}\n").start()
    yield b, files["ca"]
    b.stop()


def test_mqtts_with_a_password_file_and_a_wrong_password_is_refused(tls_broker, daemon, client, tmp_path):
    broker, ca = tls_broker
    secret = tmp_path / "mqtt.pass"
    secret.write_text("s3cret pass\n")  # the first line; the newline is not part of it
    auth = {"broker": f"mqtts://127.0.0.1:{broker.port}", "ca_file": str(ca), "username": "fleet",
            "password_file": str(secret)}
    daemon({"state_dir": str(tmp_path / "v"), "vehicle": {"sysid": 5},
            "channels": [{"name": "fleet", "type": "mqtt", "topic": "gcsd/tls", "role": "vehicle", **auth}]})
    ground = daemon({"state_dir": str(tmp_path / "g"), "vehicle": {"type": "companion", "sysid": GROUND_SYSID},
                     "channels": [udp_channel("gcs"),
                                  {"name": "fleet", "type": "mqtt", "topic": "gcsd/tls", "role": "ground", **auth}]})
    gcs = client(udp_url(ground.port("gcs")))
    assert (5, 1) in heard_all(gcs, {(5, 1)})
    assert param_value(gcs, (5, 1), b"SYSID_THISMAV") == 5.0

    wrong = tmp_path / "wrong.pass"
    wrong.write_text("guess\n")
    config = parse_config(yaml.safe_dump({"channels": [{"name": "x", "type": "mqtt", "topic": "gcsd/tls",
                                                        **auth, "password_file": str(wrong)}]}), "x.yaml")

    async def attempt():
        link = MqttLink(Channel(0, config.channels[0]), config.channels[0].mqtt)
        await link.open()

    with pytest.raises(OSError, match="refused"):
        asyncio.run(attempt())  # run_channel logs it and retries with its capped backoff


def test_two_ground_sides_split_a_fleet_by_sysids(broker, daemon, client, tmp_path):
    topic = "gcsd/split"
    daemon(vehicle_side(tmp_path, "v", broker, topic, count=6, sysid=1))
    stations = []
    for name, sysids in (("low", "1-3"), ("high", [4, 5, 6])):
        conf = ground_side(tmp_path, broker, topic, sysids=sysids)
        conf["state_dir"] = str(tmp_path / name)
        stations.append(client(udp_url(daemon(conf).port("gcs"))))
    low, high = stations
    heard_all(low, {(1, 1), (2, 1), (3, 1)})
    heard_all(high, {(4, 1), (5, 1), (6, 1)})
    pump([low, high], 1.2)  # one more heartbeat period of every vehicle, in the same window for both
    seen_low = {r.src[0] for r in low.since(0, "HEARTBEAT")} - {GROUND_SYSID}
    seen_high = {r.src[0] for r in high.since(0, "HEARTBEAT")} - {GROUND_SYSID}
    assert (seen_low, seen_high) == ({1, 2, 3}, {4, 5, 6})
    assert param_value(high, (5, 1), b"SYSID_THISMAV") == 5.0


def test_no_forward_on_the_mqtt_channel_is_honoured_like_on_any_channel(broker, daemon, client, tmp_path):
    topic = "gcsd/closed"
    daemon(vehicle_side(tmp_path, "v", broker, topic, count=2, sysid=1))
    ground = daemon(ground_side(tmp_path, broker, topic, options=["no_forward"]))
    gcs = client(udp_url(ground.port("gcs")))
    seen = heartbeats(gcs, 2.5)
    assert (GROUND_SYSID, 191) in seen, "the ground side itself is heard"
    assert ground.stats("fleet")["packets_in"] > 0, "the fleet's frames reach the ground side"
    assert not {1, 2} & {s for s, _ in seen}, "but a no_forward channel's frames are not forwarded"


def test_garbage_oversized_and_spoofed_messages_are_counted_and_dropped(broker, daemon, client, tap, tmp_path):
    topic = "gcsd/hostile"
    daemon(vehicle_side(tmp_path, "v", broker, topic, sysid=3))
    ground = daemon(ground_side(tmp_path, broker, topic))
    gcs = client(udp_url(ground.port("gcs")))
    assert (3, 1) in heard_all(gcs, {(3, 1)})
    before = ground.stats("fleet")["parse_errors"]
    spoofed = packed_heartbeat(9)  # a good frame from sysid 9, on vehicle 3's topic
    attacker = tap(f"{topic}/nothing")
    mark = gcs.mark()
    attacker.publish(f"{topic}/up/3/1", b"\x00garbage, not MAVLink")
    attacker.publish(f"{topic}/up/3/1", spoofed[:-4])  # truncated
    attacker.publish(f"{topic}/up/3/1", spoofed * 200)  # oversized
    attacker.publish(f"{topic}/up/3/1", spoofed)
    assert heard_all(gcs, {(3, 1)}).get((3, 1)), "the ground side still routes the fleet"
    # the vehicle's HEARTBEAT comes through its own connection to the broker, so it does not prove
    # the attacker's four messages were read: their counts are awaited (at least 0.5 s of window)
    def counted() -> bool:
        fleet = ground.stats("fleet")
        return fleet["parse_errors"] >= before + 3 and fleet["spoofed_dropped"] >= 1

    assert pump_until([gcs], counted, at_least_s=0.5), ground.stats("fleet")
    assert 9 not in {r.src[0] for r in gcs.since(mark, "HEARTBEAT")}, "the spoofed source was not routed"
    assert ground.stats("fleet")["spoofed_dropped"] == 1


def packed_heartbeat(sysid: int) -> bytes:
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=1)
    return bytes(M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, M.MAV_AUTOPILOT_ARDUPILOTMEGA, 0, 0, 0, 3).pack(mav))
