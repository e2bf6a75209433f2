"""The signing gateway and stream requests (SPEC.md "Companion routing"), with a second gcsd as
the flight controller: it requires signing (`signing.require`), so it obeys only signed frames.

The companion gcsd shares the key, links to the flight controller over UDP, and serves two
local channels: `tool` (sign_forwarded, bound to 127.0.0.1) and `lan` (an ordinary channel).
A command from the tool is signed on its way and answered; the same command from the LAN is
forwarded byte-exact, unsigned, and refused by the flight controller: its refusal is counted
(`signature_rejects`), the positive event that proves the frame arrived and was not obeyed.
"""

from __future__ import annotations

import time

from .helpers import VEHICLE, M, from_vehicle, udp_channel, udp_url, wait_for

KEY = "42" * 32
COMPANION = (1, 191)


def _channel(d, name: str) -> dict:
    return next(c for c in d.status()["channels"] if c["name"] == name)


def _poll(condition, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.05)
    return condition()


def _flight_controller(daemon, tmp_path):
    return daemon({"state_dir": str(tmp_path / "fc"), "signing": {"key": KEY, "require": True},
                   "channels": [udp_channel("link")]})


def _companion(daemon, tmp_path, fc, **fc_link):
    return daemon({
        "state_dir": str(tmp_path / "companion"), "vehicle": {"type": "companion"}, "signing": {"key": KEY},
        "channels": [{"name": "fc", "type": "udp-client", "address": f"127.0.0.1:{fc.port('link')}", **fc_link},
                     udp_channel("tool", options=["sign_forwarded"]), udp_channel("lan")]})


def _request_message(c, msgid: int) -> bytes:
    return c.command_long(M.MAV_CMD_REQUEST_MESSAGE, msgid, target=VEHICLE)


def _ack_for(msgid: int):
    return lambda r: (r.type == "COMMAND_ACK" and r.src == VEHICLE and r.msg.command == M.MAV_CMD_REQUEST_MESSAGE
                      and r.msg.result == M.MAV_RESULT_ACCEPTED)


def test_a_flight_controller_that_requires_signing_obeys_the_gateway_and_not_an_open_channel(daemon, client,
                                                                                           tmp_path):
    fc = _flight_controller(daemon, tmp_path)
    companion = _companion(daemon, tmp_path, fc)
    tool = client(udp_url(companion.port("tool")), 255, 190)
    lan = client(udp_url(companion.port("lan")), 254, 190)
    tool.heartbeat()
    lan.heartbeat()
    # the flight controller's own HEARTBEAT reaches both ground stations through the companion
    for c in (tool, lan):
        assert wait_for(c, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE, timeout=5.0, others=[tool, lan])
    rejects_before = _channel(fc, "link")["signature_rejects"]
    mark = lan.mark()
    _request_message(lan, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert _poll(lambda: _channel(fc, "link")["signature_rejects"] > rejects_before, 3.0), \
        "the LAN's command never reached the flight controller"
    tool_mark = tool.mark()
    _request_message(tool, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert wait_for(tool, _ack_for(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION), since=tool_mark, others=[tool, lan])
    assert [r for r in lan.since(mark, "COMMAND_ACK") if r.src == VEHICLE] == []  # an ACK is addressed to its sender


def test_request_streams_asks_the_flight_controller_for_telemetry(daemon, client, tmp_path):
    fc = daemon({"state_dir": str(tmp_path / "fc"),
                 "channels": [udp_channel("link", streams={name: 0 for name in (
                     "raw_sens", "ext_stat", "rc_chan", "raw_ctrl", "position", "extra1", "extra2", "extra3",
                     "params", "adsb")})]})
    companion = daemon({"state_dir": str(tmp_path / "companion"), "vehicle": {"type": "companion"},
                        "channels": [{"name": "fc", "type": "udp-client", "address": f"127.0.0.1:{fc.port('link')}",
                                      "request_streams": 4},
                                     udp_channel("gcs")]})
    gcs = client(udp_url(companion.port("gcs")), 255, 190)
    gcs.heartbeat()
    assert wait_for(gcs, from_vehicle, timeout=5.0)  # the flight controller's heartbeat: the link works
    # its streams were all 0; the companion asked for them at 4 Hz on our behalf
    assert wait_for(gcs, lambda r: r.type == "ATTITUDE" and r.src == VEHICLE, timeout=5.0)
    assert _channel(companion, "fc")["packets_out"] > 0
