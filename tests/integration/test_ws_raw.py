"""The `websocket` channel (SPEC.md "Web tools and monitoring"): binary MAVLink 2 over WebSocket,
on the HTTP port at /v1/ws/raw and on a listener of its own, with a real client (aiohttp's) and
pymavlink's parser on what it receives; a pymavlink ground station on UDP sees the effect of a
command sent over it."""

from __future__ import annotations

import asyncio

import aiohttp
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from .helpers import VEHICLE, M, is_type, packed, udp_channel, udp_url, wait_for
from .http_client import call

CONFIG = {"channels": [udp_channel("gcs"), {"name": "web", "type": "websocket", "address": "127.0.0.1:0"}]}


class Parsed:
    """pymavlink's parser over a WebSocket's binary frames (a stream: packets may span frames)."""

    def __init__(self) -> None:
        self.mav = mavlink2.MAVLink(None)
        self.mav.robust_parsing = True
        self.messages: list = []

    def feed(self, data: bytes) -> None:
        self.messages += [m for m in (self.mav.parse_buffer(data) or []) if m.get_type() != "BAD_DATA"]


async def _until(ws, parsed: Parsed, match, timeout: float = 3.0):
    end = asyncio.get_running_loop().time() + timeout
    while True:
        hit = next((m for m in parsed.messages if match(m)), None)
        if hit is not None:
            return hit
        left = end - asyncio.get_running_loop().time()
        if left <= 0:
            return None
        try:
            msg = await ws.receive(timeout=left)
        except TimeoutError:
            return None
        if msg.type == aiohttp.WSMsgType.BINARY:
            parsed.feed(msg.data)
        elif msg.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED, aiohttp.WSMsgType.CLOSING):
            return None


def _from_vehicle(name: str):
    return lambda m: m.get_type() == name and (m.get_srcSystem(), m.get_srcComponent()) == VEHICLE


async def _session(url: str, gcs_ws_url: str):
    async with aiohttp.ClientSession() as session:
        # telemetry without asking: the vehicle's heartbeat and attitude, nothing sent
        async with session.ws_connect(url) as ws:
            parsed = Parsed()
            hb = await _until(ws, parsed, _from_vehicle("HEARTBEAT"))
            att = await _until(ws, parsed, _from_vehicle("ATTITUDE"))
            # a PARAM_REQUEST_READ split across two frames: answered with PARAM_VALUE
            raw = packed(M.MAVLink_param_request_read_message(1, 1, b"SYSID_THISMAV", -1))
            await ws.send_bytes(raw[:5])
            await ws.send_bytes(raw[5:])
            pv = await _until(ws, parsed, lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "SYSID_THISMAV")
            # arm over the raw WebSocket (a pymavlink station on UDP sees the effect)
            await ws.send_bytes(packed(M.MAVLink_command_long_message(
                1, 1, M.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)))
            ack = await _until(ws, parsed, lambda m: m.get_type() == "COMMAND_ACK"
                               and m.command == M.MAV_CMD_COMPONENT_ARM_DISARM)
        # a text frame: closed with 1003; a binary client beside it goes on receiving (control)
        async with session.ws_connect(url) as text_ws, session.ws_connect(url) as binary_ws:
            await text_ws.send_str('{"message": "hello"}')
            closing = await text_ws.receive(timeout=3)
            control = await _until(binary_ws, Parsed(), _from_vehicle("HEARTBEAT"))
        # the HTTP port's /v1/ws/raw is the same channel
        async with session.ws_connect(gcs_ws_url) as ws2:
            via_http = await _until(ws2, Parsed(), _from_vehicle("HEARTBEAT"))
    return hb, att, pv, ack, closing, text_ws.close_code, control, via_http


def test_raw_websocket_streams_unasked_and_takes_commands(daemon, client):
    d = daemon(CONFIG)
    gcs = client(udp_url(d.port("gcs")))
    gcs.heartbeat()
    assert wait_for(gcs, is_type("HEARTBEAT", VEHICLE))
    own = f"ws://127.0.0.1:{d.port('web')}/"
    via_http = d.http_url().replace("http://", "ws://") + "/v1/ws/raw"
    hb, att, pv, ack, closing, code, control, over_http = asyncio.run(_session(own, via_http))
    assert hb is not None and att is not None, "telemetry flows without a request"
    assert pv is not None and pv.param_value == 1.0, "the split PARAM_REQUEST_READ was answered"
    assert ack is not None and ack.result == M.MAV_RESULT_ACCEPTED
    assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE
                    and r.msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, timeout=5), "the UDP station sees it armed"
    assert code == aiohttp.WSCloseCode.UNSUPPORTED_DATA, closing
    assert control is not None and over_http is not None
    web = next(ch for ch in d.status()["channels"] if ch["name"] == "web")
    assert web["type"] == "websocket" and web["packets_in"] >= 2 and web["packets_out"] > 0


async def _first_heartbeat(url: str):
    async with aiohttp.ClientSession() as session, session.ws_connect(url) as ws:
        return await _until(ws, Parsed(), _from_vehicle("HEARTBEAT"))


def test_raw_websocket_needs_the_token_and_is_404_without_a_channel(daemon, tmp_path):
    token = tmp_path / "token"
    token.write_text("s3cret\n")
    d = daemon({**CONFIG, "http": {"address": "127.0.0.1:0", "token_file": str(token)}})
    upgrade = {"Connection": "Upgrade", "Upgrade": "websocket", "Sec-WebSocket-Version": "13",
               "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="}
    own = f"http://127.0.0.1:{d.port('web')}/"
    assert call(own, headers=upgrade)[0] == 401
    assert call(f"{d.http_url()}/v1/ws/raw", headers=upgrade)[0] == 401
    assert asyncio.run(_first_heartbeat(own.replace("http", "ws") + "?token=s3cret")), \
        "positive control: with the token, the same listener streams"

    d2 = daemon({"channels": [udp_channel("gcs")]})
    assert call(f"{d2.http_url()}/v1/ws/raw", headers=upgrade)[0] == 404
