"""One error boundary everywhere (boundary.py): a raise in a command handler, in the signing
check or admission of a received frame, in the MQTT link's callback, in the daemon's side tasks
(stats, signing timestamp) and in the write-behind's callbacks is counted in `gcsd status`
(`errors`), and the daemon and the connection live on.

Each test breaks one part on purpose (a class-level patch, in place before the daemon is built)
and then shows, through the same daemon and the same connection, that it still answers.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time

from gcsd.daemon.daemon import Daemon
from gcsd.links.channel import Channel
from gcsd.vehicle.services.params import ParamService
from gcsd.vehicle.services.rates import RatesService
from gcsd.wire.signing import SigningManager

from .helpers import VEHICLE, M, is_ack, tcp_channel, tcp_url, udp_channel, udp_url, wait_for
from .test_mqtt import broker, tap, vehicle_side  # noqa: F401  (fixtures)
from .test_signing import KEY, sign

PING = M.MAVLINK_MSG_ID_PING


def _until(predicate, timeout_s: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.02)
    return False


def _errors(d) -> dict[str, int]:
    return d.status()["errors"]


def _answers_param_read(station) -> bool:
    mark = station.mark()
    station.send(M.MAVLink_param_request_read_message(*VEHICLE, b"SYSID_THISMAV", -1))
    return wait_for(station, lambda r: r.type == "PARAM_VALUE" and r.src == VEHICLE, since=mark) is not None


def test_a_raising_command_handler_is_counted_acked_failed_and_shown_by_gcsd_status(daemon, client,
                                                                                    monkeypatch, tmp_path):
    def broken(self, req):
        raise RuntimeError("deliberately broken command handler")

    monkeypatch.setattr(RatesService, "get_message_interval", broken)
    d = daemon({"channels": [udp_channel("gcs")]})
    station = client(udp_url(d.port("gcs")))
    station.heartbeat()
    mark = station.mark()
    station.command_long(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)
    ack = wait_for(station, is_ack(M.MAV_CMD_GET_MESSAGE_INTERVAL), since=mark)
    assert ack is not None and ack.msg.result == M.MAV_RESULT_FAILED
    assert _answers_param_read(station), "the daemon and the link live on"
    component = f"command:{M.MAV_CMD_GET_MESSAGE_INTERVAL}"
    assert _errors(d)[component] == 1
    conf = tmp_path / "same.yaml"
    conf.write_text(f"state_dir: {d.config.state_dir}\n")
    shown = subprocess.run([sys.executable, "-m", "gcsd", "status", "-c", str(conf), "--json"], check=False,
                           capture_output=True, text=True, timeout=20)
    assert shown.returncode == 0, shown.stderr
    assert json.loads(shown.stdout)["errors"][component] == 1, "gcsd status --json shows it"


def test_a_raise_in_the_signing_check_is_counted_and_the_tcp_connection_lives_on(daemon, client, monkeypatch):
    original = Daemon.verify

    def verify(self, channel, frame):
        if frame.msgid == PING:
            raise RuntimeError("deliberately broken signing check")
        return original(self, channel, frame)

    monkeypatch.setattr(Daemon, "verify", verify)
    # a key: without one (and nothing required) every frame is accepted untouched, the check never runs
    d = daemon({"signing": {"key": KEY.hex()}, "channels": [tcp_channel("tcp")]})
    station = client(tcp_url(d.port("tcp")))
    sign(station, KEY)
    station.heartbeat()
    station.send(M.MAVLink_ping_message(1, 0, 0, 0))
    station.send(M.MAVLink_ping_message(2, 0, 0, 0))
    assert _answers_param_read(station), "the same TCP connection is still served"
    assert _until(lambda: _errors(d).get("receive", 0) == 2)
    assert d.stats("tcp")["peers"] == 1


def test_a_raise_when_a_peer_is_admitted_is_counted_and_the_peer_is_served(daemon, client, monkeypatch):
    def joined(self, channel, peer):
        raise RuntimeError("deliberately broken admission hook")

    monkeypatch.setattr(Daemon, "on_peer_joined", joined)
    d = daemon({"channels": [udp_channel("gcs")]})
    station = client(udp_url(d.port("gcs")))
    station.heartbeat()
    assert _answers_param_read(station)
    assert _errors(d)["receive"] == 1
    assert d.stats("gcs")["peers"] == 1


def test_a_raise_in_the_mqtt_callback_is_counted_and_the_link_lives_on(broker, daemon, tap, monkeypatch,  # noqa: F811
                                                                       tmp_path):
    original = Channel.receive

    def receive(self, peer, data, now, datagram=False, **kwargs):
        if bytes(data).startswith(b"BOOM"):
            raise RuntimeError("deliberately broken receive")
        return original(self, peer, data, now, datagram, **kwargs)

    monkeypatch.setattr(Channel, "receive", receive)
    topic = "gcsd/boundary"
    d = daemon(vehicle_side(tmp_path, "v", broker, topic, sysid=3))
    ground = tap(f"{topic}/#")
    assert _until(lambda: any(t.startswith(f"{topic}/up/3/") for t, _ in ground.since(0)), 10.0)
    ground.publish(f"{topic}/down/3", b"BOOM")
    assert _until(lambda: _errors(d).get("mqtt_receive", 0) == 1)
    mark = ground.mark()
    request = M.MAVLink_param_request_read_message(3, 1, b"SYSID_THISMAV", -1)
    ground.publish(f"{topic}/down/3", bytes(request.pack(M.MAVLink(None, srcSystem=255, srcComponent=190))))

    def answered() -> bool:
        # the vehicle's side only: the tap also hears the test's own down/ publications, and BOOM
        # delivered after `mark` (a late broker, under load) made a strict parser raise
        parser = M.MAVLink(None)
        parser.robust_parsing = True
        up = [payload for t, payload in ground.since(mark) if t.startswith(f"{topic}/up/3/")]
        return any(m.get_type() == "PARAM_VALUE" for payload in up for m in parser.parse_buffer(payload) or [])

    assert _until(answered, 5.0), "the link still answers through the broker"


def test_a_raise_in_the_stats_task_is_counted_and_the_daemon_keeps_serving(daemon, client, monkeypatch):
    from gcsd.daemon import daemon as gcs

    def broken(self, last):
        raise RuntimeError("deliberately broken stats pass")

    monkeypatch.setattr(gcs, "STATS_INTERVAL_S", 1.0)
    monkeypatch.setattr(Daemon, "_stats_pass", broken)
    d = daemon({"channels": [udp_channel("gcs")]})
    station = client(udp_url(d.port("gcs")))
    station.heartbeat()
    assert _until(lambda: _errors(d).get("stats", 0) >= 2)
    assert _answers_param_read(station)


def test_a_raise_in_the_signing_timestamp_task_is_counted_and_the_daemon_keeps_serving(daemon, client,
                                                                                      monkeypatch):
    from gcsd.daemon import daemon as gcs

    def broken(self):
        raise RuntimeError("deliberately broken timestamp save")

    monkeypatch.setattr(gcs, "SAVE_INTERVAL_S", 0.1)
    monkeypatch.setattr(SigningManager, "persist_deadline", broken)
    d = daemon({"channels": [udp_channel("gcs")]})
    station = client(udp_url(d.port("gcs")))
    station.heartbeat()
    assert _until(lambda: _errors(d).get("signing_save", 0) >= 2)
    assert _answers_param_read(station)


def test_a_raise_in_the_write_behind_is_counted_and_parameters_still_answer(daemon, client, monkeypatch):
    original = ParamService.take_persist
    broken_once = []

    def take(self, now, force=False):
        if not force and not broken_once:
            broken_once.append(now)
            raise RuntimeError("deliberately broken persist snapshot")
        return original(self, now, force)

    monkeypatch.setattr(ParamService, "take_persist", take)
    d = daemon({"channels": [udp_channel("gcs")]})
    station = client(udp_url(d.port("gcs")))
    station.heartbeat()
    mark = station.mark()
    station.send(M.MAVLink_param_set_message(*VEHICLE, b"WPNAV_SPEED", 750.0, M.MAV_PARAM_TYPE_REAL32))
    assert wait_for(station, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == "WPNAV_SPEED",
                    since=mark) is not None
    assert _until(lambda: _errors(d).get("persist:mav.parm", 0) == 1)
    assert _answers_param_read(station)
