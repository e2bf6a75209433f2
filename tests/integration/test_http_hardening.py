"""Issue 26, the HTTP API where a web page or a hostile client still won (on 63f9fa5):

1. a page on any origin armed the vehicle with a "simple request" (POST, Content-Type text/plain,
   no preflight) and was answered `Access-Control-Allow-Origin: *`; a DNS-rebinding page did the
   same under its own host name; with signing.require the API still armed without a token;
6. hostile JSON: a 100 000-deep array was a RecursionError (500), on the WebSocket the handler died
   and the client saw close 1002; `{"value": 1e308}` for a float32 parameter was 500; "²" (which
   passes str.isdigit()) as a sysid, a tree path or a log id was 500; each counted as a daemon error.

Now: refused by reason and counted (`http.refused` in `gcsd status`), every client error is 4xx
with `{"error"}`, the WebSocket answers `{"error"}` and stays open, the daemon's error counts stay
empty. Positive controls in the same daemon: the page's own origin and a curl-style JSON POST
still arm; a read still answers `*` for dashboards. The real browser is in test_http_page.py.
"""

from __future__ import annotations

import asyncio
import json
import socket

import aiohttp
import pytest
import structlog

from .helpers import udp_channel
from .http_client import call, poll

GCS_CHANNEL = {"channels": [udp_channel("gcs")]}
JSON = {"Content-Type": "application/json"}
EVIL = "http://evil.example"


def armed(d) -> bool:
    return d.status()["vehicles"][0]["armed"]


def refused(d) -> dict:
    return d.status()["http"]["refused"]


def raw_request(host: str, port: int, text: bytes, timeout: float = 5.0) -> bytes:
    """One request exactly as written (a browser's headers, a forged Host), the whole answer."""
    with socket.create_connection((host, port), timeout=timeout) as s:
        s.sendall(text)
        chunks = []
        while chunk := s.recv(65536):
            chunks.append(chunk)
    return b"".join(chunks)


def test_a_foreign_page_cannot_arm_and_the_own_page_and_curl_still_can(daemon):
    d = daemon(GCS_CHANNEL)
    url = d.http_url()
    host, port = d.gcs.http.address
    arm = f"{url}/v1/vehicles/1/arm"
    # the browser's simple request from another origin: no preflight, text/plain
    status, headers, body, _ = call(arm, "POST", raw=b"{}", headers={"Content-Type": "text/plain", "Origin": EVIL})
    assert status == 403 and body["error"] and headers.get("Access-Control-Allow-Origin") != "*"
    # the same with JSON (a browser would have asked first: the preflight is refused too)
    assert call(arm, "POST", {}, headers={"Origin": EVIL})[0] == 403
    status, headers, _, _ = call(arm, "OPTIONS", headers={"Origin": EVIL, "Access-Control-Request-Method": "POST",
                                                          "Access-Control-Request-Headers": "content-type"})
    assert status == 403 and "Access-Control-Allow-Origin" not in headers
    # DNS rebinding: the attacker's name resolves to 127.0.0.1, the page is "same-origin" to itself
    rebound = raw_request(host, port, f"POST /v1/vehicles/1/arm HTTP/1.1\r\nHost: evil.example:{port}\r\n"
                                      f"Origin: http://evil.example:{port}\r\nContent-Type: application/json\r\n"
                                      "Content-Length: 2\r\nConnection: close\r\n\r\n{}".encode())
    assert rebound.startswith(b"HTTP/1.1 421 ")
    assert call(f"{url}/v1/status", headers={"Host": f"evil.example:{port}"})[0] == 421  # reads too
    # a form post without a Content-Type of JSON, from curl (no Origin): 415
    assert call(arm, "POST", raw=b"{}", headers={"Content-Type": "application/x-www-form-urlencoded"})[0] == 415
    assert not armed(d), "nothing of the above armed the vehicle"
    assert refused(d) == {"origin": 3, "host": 2, "content_type": 1}

    # positive controls: the page's own origin (what its fetch() sends), then curl -H 'Content-Type: application/json'
    own = f"http://{host}:{port}"
    status, headers, body, _ = call(arm, "POST", {}, headers={"Origin": own})
    assert (status, body) == (200, {"armed": True}) and headers["Access-Control-Allow-Origin"] == own
    assert headers["Vary"] == "Origin"
    assert call(f"{url}/v1/vehicles/1/disarm", "POST", {})[0] == 200
    assert poll(lambda: not armed(d))
    status, _, body, _ = call(arm, "POST", raw=b"", headers=JSON)  # curl -X POST -H 'Content-Type: application/json'
    assert (status, body) == (200, {"armed": True})
    status, headers, _, _ = call(arm, "OPTIONS", headers={"Origin": own, "Access-Control-Request-Method": "POST"})
    assert status == 204 and headers["Access-Control-Allow-Origin"] == own
    assert call(f"{url}/v1/status", headers={"Origin": EVIL})[1]["Access-Control-Allow-Origin"] == "*"  # reads
    assert call(f"{url}/v1/status", headers={"Host": f"localhost:{port}"})[0] == 200
    assert refused(d) == {"origin": 3, "host": 2, "content_type": 1}
    assert d.status()["errors"] == {}


async def _handshake(url: str, headers: dict) -> int:
    async with aiohttp.ClientSession() as session:
        try:
            async with session.ws_connect(url, headers=headers):
                return 101
        except aiohttp.WSServerHandshakeError as exc:
            return exc.status


def test_a_foreign_page_cannot_open_the_websockets(daemon):
    d = daemon(GCS_CHANNEL)
    host, port = d.gcs.http.address
    for path in ("/v1/ws/mavlink", "/v1/ws/status"):
        ws = f"ws://{host}:{port}{path}"
        assert asyncio.run(_handshake(ws, {"Origin": EVIL})) == 403, path
        assert asyncio.run(_handshake(ws, {"Origin": f"http://{host}:{port}"})) == 101, path  # the page's own
        assert asyncio.run(_handshake(ws, {})) == 101, path  # a script
    assert refused(d) == {"origin": 2}


def test_signing_required_without_a_token_makes_the_api_read_only(daemon):
    with structlog.testing.capture_logs() as logs:
        d = daemon({**GCS_CHANNEL, "signing": {"key": "ab" * 32, "require": True}})
        url = d.http_url()
        assert poll(lambda: any(e["event"] == "http_read_only" for e in logs))
    assert call(f"{url}/v1/vehicles/1/arm", "POST", {})[0] == 403
    assert call(f"{url}/v1/vehicles/1/parameters/ANGLE_MAX", "PUT", {"value": 3000})[0] == 403
    assert call(f"{url}/v1/mavlink", "POST", {"header": {"system_id": 255, "component_id": 190},
                                              "message": {"type": "PING"}})[0] == 403

    async def ws_send() -> tuple[dict, dict]:
        async with aiohttp.ClientSession() as session, \
                session.ws_connect(url.replace("http", "ws") + "/v1/ws/mavlink?filter=^HEARTBEAT$") as ws:
            await ws.send_str(json.dumps({"header": {"system_id": 255, "component_id": 190},
                                          "message": {"type": "PING"}}))
            answer = json.loads((await ws.receive(timeout=5)).data)
            while "error" in (frame := json.loads((await ws.receive(timeout=5)).data)):
                pass
            return answer, frame  # the socket stayed open and streams: the read side works

    answer, frame = asyncio.run(ws_send())
    assert "read-only" in answer["error"] and frame["message"]["type"] == "HEARTBEAT"
    status, _, body, _ = call(f"{url}/v1/vehicles/1/parameters/ANGLE_MAX")  # reads: the positive control
    assert status == 200 and body["name"] == "ANGLE_MAX"
    assert d.status()["http"]["read_only"] is True and refused(d) == {"read_only": 4}
    assert not armed(d)


def test_with_signing_required_the_token_holder_still_arms(daemon, tmp_path):
    token = tmp_path / "token"
    token.write_text("t0ken\n")
    d = daemon({**GCS_CHANNEL, "signing": {"key": "ab" * 32, "require": True},
                "http": {"address": "127.0.0.1:0", "token_file": str(token)}})
    url = d.http_url()
    assert d.status()["http"]["read_only"] is False
    assert call(f"{url}/v1/vehicles/1/arm", "POST", {})[0] == 401
    status, _, body, _ = call(f"{url}/v1/vehicles/1/arm", "POST", {}, headers={"Authorization": "Bearer t0ken"})
    assert (status, body) == (200, {"armed": True})


DEEP = b"[" * 100_000 + b"]" * 100_000


@pytest.mark.parametrize(("method", "path", "raw", "status"), [
    ("POST", "/v1/mavlink", DEEP, 400),
    ("PUT", "/v1/vehicles/1/mission", b'{"fileType": ' + b'{"a": ' * 5000 + b"1" + b"}" * 5000 + b"}", 400),
    ("PUT", "/v1/vehicles/1/parameters/ANGLE_MAX", b'{"value": 1e308}', 422),
    ("PUT", "/v1/vehicles/1/parameters/ANGLE_MAX", b'{"value": -3.5e38}', 422),
    ("PUT", "/v1/vehicles/1/parameters/ANGLE_MAX", b'{"value": ' + b"9" * 400 + b"}", 422),
    ("GET", "/v1/vehicles/%C2%B2/parameters", None, 404),
    ("GET", "/v1/mavlink/vehicles/%C2%B2", None, 404),
    ("GET", "/v1/mavlink/vehicles/1/components/%D9%A1", None, 404),  # ARABIC-INDIC DIGIT ONE
    ("GET", "/v1/logs/%C2%B2", None, 404),
    ("GET", "/v1/logs/1?sysid=%C2%B2", None, 404),
])
def test_hostile_input_is_a_4xx_json_answer_never_a_daemon_error(daemon, method, path, raw, status):
    d = daemon(GCS_CHANNEL)
    url = d.http_url()
    got, headers, body, _ = call(url + path, method, raw=raw)
    assert got == status and headers["Content-Type"].startswith("application/json") and body["error"]
    assert call(f"{url}/v1/vehicles/1/parameters/ANGLE_MAX")[0] == 200  # the positive control
    assert d.status()["errors"] == {}


def test_the_websocket_answers_hostile_json_and_stays_open(daemon):
    d = daemon(GCS_CHANNEL)
    ws_url = d.http_url().replace("http", "ws") + "/v1/ws/mavlink?filter=^STATUSTEXT$"
    text = {"header": {"system_id": 7, "component_id": 191},
            "message": {"type": "STATUSTEXT", "severity": {"type": "MAV_SEVERITY_INFO"}, "text": "still open"}}

    async def body():
        async with aiohttp.ClientSession() as session, session.ws_connect(ws_url) as ws:
            answers = []
            for hostile in (DEEP.decode(), "{" * 70 + "}" * 70, "[1e999]", "\x00"):
                await ws.send_str(hostile)
                answers.append(json.loads((await ws.receive(timeout=5)).data))
            await ws.send_str(json.dumps(text))  # the positive control: the same socket still sends
            echo = json.loads((await ws.receive(timeout=5)).data)
            return answers, echo, ws.closed

    answers, echo, closed = asyncio.run(body())
    assert all("error" in a for a in answers) and not closed
    assert echo["message"]["text"][:10] == list("still open")
    assert d.status()["errors"] == {}
