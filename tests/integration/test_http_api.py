"""The HTTP and WebSocket API on the real daemon (SPEC.md "HTTP and WebSocket API").

mavlink2rest's routes and shapes are compared with the examples of its repository (README.md,
tests/run.py); posted commands are shown to take effect by a pymavlink ground station on a real
UDP channel; every gcsd route; bad input gets a 4xx JSON answer and the daemon goes on serving.
"""

from __future__ import annotations

import re
import urllib.request

import pytest

from .helpers import VEHICLE, M, is_type, udp_channel, udp_url, wait_for
from .http_client import call, poll, ws_frames, ws_handshake_status
from .test_signing import sign

GCS_CHANNEL = {"channels": [udp_channel("gcs")]}
ENTRY = "/v1/mavlink/vehicles/1/components/1/messages"
ARM_README = {  # mavlink2rest README.md, "Request vehicle to be armed"
    "header": {"system_id": 255, "component_id": 240, "sequence": 0},
    "message": {"type": "COMMAND_LONG", "param1": 1.0, "param2": 0.0, "param3": 0.0, "param4": 0.0,
                "param5": 0.0, "param6": 0.0, "param7": 0.0, "command": {"type": "MAV_CMD_COMPONENT_ARM_DISARM"},
                "target_system": 1, "target_component": 1, "confirmation": 1},
}


@pytest.fixture
def api(daemon, client):
    d = daemon(GCS_CHANNEL)
    gcs = client(udp_url(d.port("gcs")))
    gcs.heartbeat()
    assert wait_for(gcs, is_type("HEARTBEAT", VEHICLE)), "the ground station hears the vehicle"
    return d, d.http_url(), gcs


def entry_now(url: str, name: str):
    status, _, body, _ = call(f"{url}{ENTRY}/{name}")
    return body if status == 200 else None


def entry(url: str, name: str, timeout: float = 5.0, counter: int = 1):
    """The tree's entry for one of the vehicle's messages once it has been counted `counter` times."""
    def ready():
        e = entry_now(url, name)
        return e if e and e["status"]["time"]["counter"] >= counter else None
    return poll(ready, timeout)


def test_tree_shape_paths_and_status_as_mavlink2rest(api):
    _, url, _ = api
    hb = entry(url, "HEARTBEAT", counter=3)
    assert hb, "three heartbeats in the tree"
    # tests/run.py: type, autopilot.type, frequency > 0.95, base_mode.bits
    assert hb["message"]["type"] == "HEARTBEAT" and hb["message"]["autopilot"]["type"]
    assert hb["status"]["time"]["frequency"] > 0.95
    assert isinstance(hb["message"]["base_mode"]["bits"], int)
    assert hb["message"]["mavtype"] == {"type": "MAV_TYPE_QUADROTOR"}
    # tests/run.py "Test pretty": the pretty heartbeat entry has 26 line breaks
    assert call(f"{url}{ENTRY}/HEARTBEAT")[3].count("\n") == 26
    status, headers, whole, _ = call(f"{url}/v1/mavlink")
    assert status == 200 and headers["Content-Type"].startswith("application/json")
    vehicle = whole["vehicles"]["1"]
    assert vehicle["id"] == 1 and vehicle["components"]["1"]["id"] == 1
    assert set(vehicle["components"]["1"]["messages"]["ATTITUDE"]) == {"message", "status"}
    assert set(hb["status"]["time"]) == {"counter", "first_update", "frequency", "last_update"}
    # README.md examples: a field, a time, and the same without /v1
    roll = call(f"{url}{ENTRY}/ATTITUDE/message/roll")[2]
    assert isinstance(roll, float)
    last = call(f"{url}{ENTRY}/ATTITUDE/status/time/last_update")[2]
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d+[+-]\d\d:\d\d", last)
    assert call(f"{url}/mavlink/vehicles/1/components/1/messages/ATTITUDE/message/type")[2] == "ATTITUDE"
    # where mavlink2rest answers 200 "None", gcsd answers 404 with a JSON error
    for path in ("/v1/mavlink/vehicles/9", f"{ENTRY}/NOT_HERE", f"{ENTRY}/ATTITUDE/message/nope", "/v1/nope"):
        status, headers, body, _ = call(url + path)
        assert status == 404 and "error" in body, path
    # the ground station's own heartbeat (routed traffic) is in the tree too
    assert call(f"{url}/v1/mavlink/vehicles/255/components/190/messages/HEARTBEAT/message/mavtype")[2] == \
        {"type": "MAV_TYPE_GCS"}


def test_own_telemetry_without_any_ground_station(daemon):
    d = daemon({"channels": [udp_channel("gcs")]})  # nobody connected on the MAVLink side
    url = d.http_url()
    att = entry(url, "ATTITUDE", counter=10)
    assert att and att["message"]["type"] == "ATTITUDE"
    assert d.stats("gcs")["packets_out"] == 0  # nothing went out on MAVLink: the tree has its own link
    freq = att["status"]["time"]["frequency"]
    assert 2.0 < freq < 12.0  # the extra1 stream's default (5 Hz), counted once


def test_helper_and_info(api):
    _, url, _ = api
    status, _, body, _ = call(f"{url}/v1/helper/mavlink?name=HEARTBEAT")
    assert status == 200
    assert body["header"] == {"system_id": 255, "component_id": 0, "sequence": 0}  # README.md's template
    assert body["message"]["mavtype"] == {"type": "MAV_TYPE_GENERIC"} and body["message"]["base_mode"] == {"bits": 0}
    status, _, body, _ = call(f"{url}/helper/mavlink?name=NOPE")
    assert status == 404 and body == {"error": "Invalid message name."}
    status, _, body, _ = call(f"{url}/info")
    assert status == 200 and body["version"] >= 0 and body["service"]["name"] == "gcsd"
    assert len(body["service"]["sha"]) != 0  # tests/run.py "Test info"


def test_posted_arm_takes_effect_for_the_ground_station(api):
    _, url, gcs = api
    status, _, _, text = call(f"{url}/v1/mavlink", "POST", ARM_README)
    assert (status, text) == (200, "")
    armed = wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE
                     and r.msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, timeout=5)
    assert armed, "the ground station sees the vehicle armed"
    bits = poll(lambda: call(f"{url}{ENTRY}/HEARTBEAT/message/base_mode/bits")[2] & 128)
    assert bits  # tests/run.py: vehicle_mode() & 128
    ack = call(f"{url}/v1/mavlink/vehicles/1/components/1/messages/COMMAND_ACK/message")[2]
    assert ack["command"] == {"type": "MAV_CMD_COMPONENT_ARM_DISARM"} and ack["result"] == {"type": "MAV_RESULT_ACCEPTED"}
    # the posted message itself is in the tree under its header, as mavlink2rest keeps it
    assert call(f"{url}/v1/mavlink/vehicles/255/components/240/messages/COMMAND_LONG/message/param1")[2] == 1.0


def test_posted_broadcast_is_routed_to_the_ground_station(api):
    _, url, gcs = api
    text = {"header": {"system_id": 7, "component_id": 191, "sequence": 0},
            "message": {"type": "STATUSTEXT", "severity": {"type": "MAV_SEVERITY_INFO"}, "text": "from http"}}
    assert call(f"{url}/v1/mavlink", "POST", text)[0] == 200
    got = wait_for(gcs, lambda r: r.type == "STATUSTEXT" and r.src == (7, 191))
    assert got and got.msg.text == "from http"


def test_websocket_filter_stream_and_send(api):
    _, url, gcs = api
    ws = url.replace("http://", "ws://") + "/v1/ws/mavlink"
    frames = ws_frames(ws + "?filter=^ATTITUDE$", 8)
    assert len(frames) == 8 and {f["message"]["type"] for f in frames} == {"ATTITUDE"}
    assert set(frames[0]["header"]) == {"system_id", "component_id", "sequence"}
    assert frames[0]["header"]["system_id"] == 1
    everything = ws_frames(ws, 30)  # positive control: without a filter, more than one kind
    assert len({f["message"]["type"] for f in everything}) > 1
    rc = ws_frames(ws + "?filter=RC_.*", 6)  # README.md: RC_.* takes RC_CHANNELS and RC_CHANNELS_RAW
    assert rc and all(f["message"]["type"].startswith("RC_CHANNELS") for f in rc)
    # a message sent over the WebSocket is sent; a bad one gets {"error"} and the socket stays open
    arm = dict(ARM_README)
    replies = ws_frames(ws + "?filter=^COMMAND_ACK$", 2, send=["{not json", {"header": ARM_README["header"],
                        "message": {"type": "NOPE"}}, arm])
    assert "error" in replies[0] and "error" in replies[1]
    assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE
                    and r.msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, timeout=5)
    assert call(ws.replace("ws://", "http://").replace("/v1/ws/mavlink", "/v1/ws/mavlink?filter=(") ,
                headers={"Connection": "Upgrade", "Upgrade": "websocket", "Sec-WebSocket-Version": "13",
                         "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="})[0] == 400


def test_gcsd_routes(api):
    _, url, gcs = api
    status = call(f"{url}/v1/status")[2]
    assert [c["name"] for c in status["channels"]] == ["gcs", "http"]
    assert status["vehicles"][0]["sysid"] == 1 and status["http_address"].endswith(url.rsplit(":", 1)[1])
    http = next(c for c in status["channels"] if c["name"] == "http")
    assert http["type"] == "local" and http["address"] == status["http_address"] and http["drops"] == 0
    params = call(f"{url}/v1/vehicles/1/parameters")[2]
    assert params["SYSID_THISMAV"] == 1 and len(params) > 500
    assert call(f"{url}/v1/vehicles/1/parameters/WPNAV_SPEED")[2] == {
        "name": "WPNAV_SPEED", "value": 1000.0, "type": "MAV_PARAM_TYPE_REAL32"}
    mark = gcs.mark()
    status, _, body, _ = call(f"{url}/v1/vehicles/1/parameters/WPNAV_SPEED", "PUT", {"value": 725})
    assert (status, body["value"]) == (200, 725.0)
    seen = wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == "WPNAV_SPEED", since=mark)
    assert seen and seen.msg.param_value == 725.0  # the ground station is told, as after its own PARAM_SET
    before = call(f"{url}/v1/vehicles/1/parameters/FORMAT_VERSION")[2]["value"]
    status, _, body, _ = call(f"{url}/v1/vehicles/1/parameters/FORMAT_VERSION", "PUT", {"value": before + 1})
    assert status == 422 and "read-only" in body["error"]  # refused as a ground station's PARAM_SET is
    assert call(f"{url}/v1/vehicles/1/parameters/FORMAT_VERSION")[2]["value"] == before
    assert call(f"{url}/v1/vehicles/1/parameters/NOPE")[0] == 404
    assert call(f"{url}/v1/vehicles/2/parameters")[0] == 404
    assert call(f"{url}/v1/vehicles/1/parameters/WPNAV_SPEED", "PUT", {"value": "fast"})[0] == 422
    # mode, arm, disarm: the ground station sees each
    assert call(f"{url}/v1/vehicles/1/mode", "POST", {"mode": "GUIDED"})[:1] == (200,)
    guided = {v: k for k, v in M.mode_mapping_acm.items()}["GUIDED"] if hasattr(M, "mode_mapping_acm") else 4
    assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE and r.msg.custom_mode == guided)
    status, _, body, _ = call(f"{url}/v1/vehicles/1/mode", "POST", {"mode": "WARP"})
    assert status == 422 and "unknown mode" in body["error"]
    assert call(f"{url}/v1/vehicles/1/arm", "POST", {})[0] == 200
    assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE
                    and r.msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
    assert call(f"{url}/v1/vehicles/1/disarm", "POST", {})[0] == 200
    assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == VEHICLE
                    and not r.msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)


def test_logs_list_and_file(daemon, tmp_path):
    logs = tmp_path / "state" / "logs"
    logs.mkdir(parents=True)
    content = b"\xa3\x95" + bytes(range(256)) * 40
    (logs / "00000001.BIN").write_bytes(content)
    d = daemon(GCS_CHANNEL)
    url = d.http_url()
    listed = call(f"{url}/v1/logs")[2]
    assert [(e["sysid"], e["id"], e["name"], e["size"]) for e in listed] == [(1, 1, "00000001.BIN", 10242)]
    status, headers, _, _ = call(f"{url}/v1/logs/1")
    assert status == 200 and headers["Content-Length"] == "10242"
    with urllib.request.urlopen(f"{url}/v1/logs/1?sysid=1", timeout=5) as response:
        assert response.read() == content
    assert call(f"{url}/v1/logs/2")[0] == 404 and call(f"{url}/v1/logs/x")[0] == 404
    assert call(f"{url}/v1/logs/1?sysid=9")[0] == 404


def test_mission_plan_round_trip_and_bad_plans(api):
    from tests.unit.test_http_plan import QGC_PLAN

    _, url, gcs = api
    status, _, body, _ = call(f"{url}/v1/vehicles/1/mission", "PUT", QGC_PLAN)
    assert (status, body) == (200, {"items": 3, "fence": 0, "rally": 0})
    plan = call(f"{url}/v1/vehicles/1/mission")[2]
    items = plan["mission"]["items"]
    assert [i["command"] for i in items] == [22, 16, 178]
    assert items[1]["params"][4:] == [-35.3625, 149.1655, 30.0] and items[1]["params"][3] is None
    # a ground station downloads the same mission: home, then items 1..N
    gcs.send(M.MAVLink_mission_request_list_message(1, 1, 0))
    count = wait_for(gcs, is_type("MISSION_COUNT", VEHICLE))
    assert count and count.msg.count == 4
    bad = {**QGC_PLAN, "mission": {**QGC_PLAN["mission"], "items": [{**QGC_PLAN["mission"]["items"][0], "command": 16,
                                                                      "params": [0, 0, 0, 0, 95.0, 0, 10]}]}}
    status, _, body, _ = call(f"{url}/v1/vehicles/1/mission", "PUT", bad)
    assert status == 422 and "INVALID_PARAM5" in body["error"]
    assert call(f"{url}/v1/vehicles/1/mission", "PUT", {"fileType": "Plan"})[0] == 422
    assert [i["command"] for i in call(f"{url}/v1/vehicles/1/mission")[2]["mission"]["items"]] == [22, 16, 178]


@pytest.mark.parametrize("raw,status", [
    (b"{not json", 400), (b"\xff\xfe", 400), (b"NaN", 400), (b"[]", 400),
    (b'{"header": {"system_id": 1, "component_id": 1}, "message": {"type": "NOPE"}}', 404),
    (b'{"header": {"system_id": 1, "component_id": 1}, "message": {"type": "PING", "seq": "x"}}', 422),
    (b'{"header": {"system_id": 300, "component_id": 1}, "message": {"type": "PING"}}', 422),
])
def test_bad_posts_are_4xx_json(api, raw, status):
    _, url, _ = api
    got, headers, body, _ = call(f"{url}/v1/mavlink", "POST", raw=raw, headers={"Content-Type": "application/json"})
    assert got == status and headers["Content-Type"].startswith("application/json") and body["error"]


def test_a_10_mb_body_is_413_and_the_daemon_still_serves(api):
    d, url, gcs = api
    status, _, body, _ = call(f"{url}/v1/mavlink", "POST", raw=b"x" * (10 << 20))
    assert status == 413 and "error" in body
    status, _, body, _ = call(f"{url}/v1/vehicles/1/mission", "PUT", raw=b"[" * (2 << 20))
    assert status == 413
    assert call(f"{url}/v1/status")[0] == 200
    mark = gcs.mark()
    assert wait_for(gcs, is_type("HEARTBEAT", VEHICLE), since=mark)
    assert call(f"{url}/v1/mavlink", "DELETE")[0] == 405
    assert d.status()["errors"] == {}


def test_token(daemon, tmp_path):
    token_file = tmp_path / "token"
    token_file.write_text("s3cret-token\nignored\n")
    d = daemon({**GCS_CHANNEL, "http": {"address": "127.0.0.1:0", "token_file": str(token_file)}})
    url = d.http_url()
    status, headers, body, _ = call(f"{url}/v1/status")
    assert status == 401 and headers["WWW-Authenticate"].startswith("Bearer") and "error" in body
    assert call(f"{url}/v1/status", headers={"Authorization": "Bearer wrong"})[0] == 401
    assert call(f"{url}/v1/status", headers={"Authorization": "Bearer s3cret-token"})[0] == 200
    assert call(f"{url}/v1/mavlink?token=s3cret-token")[0] == 200
    assert call(f"{url}/?token=s3cret-token")[0] == 200
    assert call(f"{url}/favicon.ico")[0] == 200  # the browser asks for it without the token
    ws = url.replace("http://", "ws://") + "/v1/ws/mavlink"
    assert ws_handshake_status(ws) == 401
    assert ws_handshake_status(ws, {"Authorization": "Bearer s3cret-token"}) == 101
    assert ws_handshake_status(ws + "?token=s3cret-token") == 101


def test_null_address_turns_the_api_off(daemon):
    d = daemon({**GCS_CHANNEL, "http": {"address": None}})
    assert d.gcs.http is None
    assert [c["name"] for c in d.status()["channels"]] == ["gcs"]


def test_signing_posts_go_out_signed(daemon, client):
    key = "ab" * 32
    d = daemon({**GCS_CHANNEL, "signing": {"key": key}})
    gcs = client(udp_url(d.port("gcs")))
    sign(gcs, bytes.fromhex(key), link_id=1)
    gcs.heartbeat()
    assert wait_for(gcs, is_type("HEARTBEAT", VEHICLE))
    text = {"header": {"system_id": 7, "component_id": 191, "sequence": 0},
            "message": {"type": "STATUSTEXT", "severity": {"type": "MAV_SEVERITY_INFO"}, "text": "signed"}}
    assert call(f"{d.http_url()}/v1/mavlink", "POST", text)[0] == 200
    got = wait_for(gcs, lambda r: r.type == "STATUSTEXT" and r.src == (7, 191))
    assert got and got.raw[2] & M.MAVLINK_IFLAG_SIGNED
    assert got.raw[-13] == d.gcs.http.face.channel.index  # link id: the http channel's index


def test_a_taken_port_does_not_stop_the_daemon_and_is_tried_again(daemon, client):
    import socket

    holder = socket.socket()
    holder.bind(("127.0.0.1", 0))
    holder.listen()
    port = holder.getsockname()[1]
    try:
        d = daemon({**GCS_CHANNEL, "http": {"address": f"127.0.0.1:{port}"}})
        gcs = client(udp_url(d.port("gcs")))
        gcs.heartbeat()
        assert wait_for(gcs, is_type("HEARTBEAT", VEHICLE)), "the daemon flies without its HTTP face"
        assert d.gcs.http.address is None
    finally:
        holder.close()
    assert poll(lambda: d.gcs.http.address == ("127.0.0.1", port), timeout=8.0)
    assert call(f"http://127.0.0.1:{port}/v1/status")[0] == 200


def test_websocket_clients_are_bounded(api):
    import asyncio

    import aiohttp

    from gcsd.api.http.routes import MAX_WEBSOCKETS

    _, url, _ = api
    ws_url = url.replace("http://", "ws://") + "/v1/ws/mavlink?filter=^HEARTBEAT$"

    async def body():
        async with aiohttp.ClientSession() as session:
            sockets = [await session.ws_connect(ws_url) for _ in range(MAX_WEBSOCKETS)]
            with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                await session.ws_connect(ws_url)
            await sockets.pop().close()
            for _ in range(50):  # the server sees the close, then takes a new one
                try:
                    sockets.append(await session.ws_connect(ws_url))
                    break
                except aiohttp.WSServerHandshakeError:
                    await asyncio.sleep(0.05)
            taken = len(sockets)
            for ws in sockets:
                await ws.close()
            return refused.value.status, taken

    status, taken = asyncio.run(body())
    assert status == 503 and taken == MAX_WEBSOCKETS
    assert call(f"{url}/v1/status")[0] == 200


def cockpit_timesync(ts1: int) -> dict:
    """Cockpit's latency probe as it posts it: TIMESYNC with current MAVLink's extension fields
    target_system and target_component, which pymavlink's dialect lacks (issue 27)."""
    return {"header": {"system_id": 255, "component_id": 240, "sequence": 0},
            "message": {"type": "TIMESYNC", "tc1": 0, "ts1": ts1, "target_system": 1, "target_component": 1}}


def test_cockpits_timesync_with_extension_fields_is_answered_over_http_and_the_websocket(api):
    _, url, _ = api
    status, _, body, _ = call(f"{url}/v1/mavlink", "POST", cockpit_timesync(1_234_567_000))
    assert status == 200, body

    def answered():
        e = entry_now(url, "TIMESYNC")
        return e if e and e["message"]["ts1"] == 1_234_567_000 else None

    got = poll(answered, 5.0)
    assert got and got["message"]["tc1"] > 0, "the vehicle's answer, in the tree"
    ws = url.replace("http://", "ws://") + "/v1/ws/mavlink?filter=^TIMESYNC$"
    frames = ws_frames(ws, 4, send=[cockpit_timesync(7_654_321_000)], timeout=3.0)  # ours and the answer
    answers = [f for f in frames if f["header"]["system_id"] == 1 and f["message"]["ts1"] == 7_654_321_000]
    assert answers and answers[0]["message"]["tc1"] > 0, frames
    # a field current MAVLink does not have is still refused, by name
    bad = cockpit_timesync(1)
    bad["message"]["target_sys"] = 1
    status, _, body, _ = call(f"{url}/v1/mavlink", "POST", bad)
    assert status >= 400 and "target_sys" in body["error"]
