"""The aiohttp application: mavlink2rest's routes, gcsd's own, the page; errors and the token.

Why aiohttp (not Starlette on uvicorn): one maintained package gives the server, WebSockets and
the client the tests use; it runs on the daemon's own loop through `AppRunner`/`TCPSite` with no
server object that wants to own the loop or the signals (uvicorn installs its own handlers and
needs a separate WebSocket library), and its HTTP parser is C.

Routes (each mavlink2rest route is also served without `/v1`, as mavlink2rest does):
  GET  /v1/mavlink[/PATH]          the message tree or any sub-path (gcsd.api.http.tree); 404 if none
  POST /v1/mavlink                 {"header", "message"}: sent (Api.post); 200 with an empty body
  GET  /v1/helper/mavlink?name=N   a template (404 {"error": "Invalid message name."})
  GET  /v1/ws/mavlink?filter=RE&sysid=N&compid=M   WebSocket: frames out (gcsd.api.http.hub),
                                   messages in; also at /mavlink2rest/ws/mavlink (BlueOS's proxy path)
  GET  /v1/ws/raw                  WebSocket: binary MAVLink 2, a peer of the websocket channel
                                   (gcsd.links.websocket); 404 without one
  GET  /info                       mavlink2rest's service description (name "gcsd")
  GET  /v1/status                  `gcsd status --json`'s document
  GET  /v1/ws/status               WebSocket: the same document every second (gcsd.api.http.statuspage)
  GET  /v1/vehicles/{sysid}/parameters[/{NAME}], PUT .../parameters/{NAME} {"value": n}
  GET/PUT /v1/vehicles/{sysid}/mission   a QGroundControl .plan: mission, geoFence, rallyPoints
                                   (gcsd.api.http.plan, planfence); PUT answers the item counts
  POST /v1/vehicles/{sysid}/mode {"mode": NAME}, .../arm {}, .../disarm {}
  GET  /v1/logs, /v1/logs/{id}[?sysid=S]   the flight logs (gcsd.payloads.logs.listing), one log's file
  GET  /, /favicon.ico             the status page (gcsd.api.http.statuspage)
  GET  /metrics                    Prometheus' text format (gcsd.api.http.metrics), unless `metrics: false`

Errors are JSON `{"error": "..."}`: 400 malformed JSON (nested deeper than MAX_JSON_DEPTH
included: checked before parsing), a bad message, or an id in a path that is not ASCII digits,
404 an unknown route,
path, message name, vehicle or parameter, 405 a wrong method, 413 a body over MAX_BODY_BYTES,
422 a value of the wrong type or range, an unknown mode or a bad plan (nothing of it stored), 409
a command the vehicle refused or a plan while a ground station uploads that type, 408 a body
not received within BODY_TIMEOUT_S, 503 beyond MAX_WEBSOCKETS WebSocket clients, 504 no answer
from a vehicle. Nothing a client sends is a daemon error: only an exception in a handler is
counted (`http` in the daemon's error counts) and answered 500; the daemon goes on. With
`http.token_file`, every request but the favicon needs `Authorization: Bearer TOKEN` or
`?token=TOKEN` (a browser's WebSocket cannot set headers); without it: 401 with `WWW-Authenticate: Bearer`.
Before any handler, gcsd.api.http.guard decides whether a request may change state (Host,
Origin, Content-Type, read-only) and which CORS headers it gets. The WebSocket answers a bad
message with `{"error"}` and stays open.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import math
import re
from typing import Protocol

from aiohttp import WSMsgType, web

from gcsd.api.http import statuspage
from gcsd.api.http.body import MAX_BODY_BYTES, RequestFailed, ascii_id, parse_json
from gcsd.api.http.guard import READ_ONLY_TEXT, Guard
from gcsd.api.http.hub import Hub
from gcsd.api.http.mavjson import FLOAT32_MAX, BadMessage, UnknownMessage, parse_envelope, template
from gcsd.api.http.plan import PlanError
from gcsd.api.http.tree import MessageTree

BODY_TIMEOUT_S = 5.0
API = web.AppKey("api", object)
GUARD = web.AppKey("guard", Guard)
METRICS = web.AppKey("metrics", object)  # gcsd.api.http.metrics.Metrics, built at the first scrape
MAX_WEBSOCKETS = 64  # a client opening more gets 503: the daemon's work stays bounded
API_VERSION = 0


class Vehicle(Protocol):
    """What the routes need of one of our vehicles (gcsd.api.http.face implements it)."""

    def parameters(self) -> dict[str, float]: ...
    def parameter(self, name: str) -> dict | None: ...
    async def set_parameter(self, name: str, value: float) -> dict: ...
    def mission(self) -> dict: ...
    def put_mission(self, document: object) -> dict[str, int]: ...
    def mode_names(self) -> list[str]: ...
    async def set_mode(self, name: str) -> None: ...
    async def arm(self, armed: bool) -> None: ...


class Api(Protocol):
    tree: MessageTree
    hub: Hub

    def status(self) -> dict: ...
    def post(self, header, msg) -> None: ...
    def vehicle(self, sysid: int) -> Vehicle | None: ...
    def logs(self) -> list[dict]: ...
    def log_file(self, log_id: str, sysid: int | None = None): ...
    def failed(self, component: str) -> None: ...


def dumps(value: object) -> str:
    return json.dumps(value, indent=2, allow_nan=False)


def _json(value: object, status: int = 200) -> web.Response:
    return web.Response(text=dumps(value), status=status, content_type="application/json")


def error(status: int, text: str, headers: dict | None = None) -> web.Response:
    return web.Response(text=json.dumps({"error": text}), status=status, content_type="application/json",
                        headers=headers)


async def read_json(request: web.Request) -> object:
    try:
        body = await asyncio.wait_for(request.read(), BODY_TIMEOUT_S)  # 413 over client_max_size
    except TimeoutError:
        request.app[GUARD].count("body_timeout")
        raise RequestFailed(408, f"the body did not arrive within {BODY_TIMEOUT_S:g} s") from None
    return parse_json(body)


def build_app(api: Api, token: str | None = None, guard: Guard | None = None,
              metrics: bool = True) -> web.Application:
    guard = guard or Guard(lambda: None, token=token is not None)
    app = web.Application(client_max_size=MAX_BODY_BYTES, middlewares=[_errors(api), _gate(token, guard)])
    app[API] = api
    app[GUARD] = guard
    app[METRICS] = []
    r = app.router
    for prefix in ("/v1", ""):
        r.add_get(prefix + "/mavlink", mavlink_get)
        r.add_get(prefix + "/mavlink/{path:.*}", mavlink_get)
        r.add_post(prefix + "/mavlink", mavlink_post)
        r.add_get(prefix + "/helper/mavlink", helper)
        r.add_get(prefix + "/ws/mavlink", websocket)
    r.add_get("/mavlink2rest/ws/mavlink", websocket)  # where Cockpit looks behind BlueOS's proxy
    r.add_get("/v1/ws/raw", raw_websocket)
    r.add_get("/info", info)
    r.add_get("/v1/status", status)
    r.add_get("/v1/vehicles/{sysid}/parameters", parameters)
    r.add_get("/v1/vehicles/{sysid}/parameters/{name}", parameter)
    r.add_put("/v1/vehicles/{sysid}/parameters/{name}", parameter_put)
    r.add_get("/v1/vehicles/{sysid}/mission", mission)
    r.add_put("/v1/vehicles/{sysid}/mission", mission_put)
    r.add_post("/v1/vehicles/{sysid}/mode", mode)
    r.add_post("/v1/vehicles/{sysid}/arm", arm)
    r.add_post("/v1/vehicles/{sysid}/disarm", disarm)
    r.add_get("/v1/logs", logs)
    r.add_get("/v1/logs/{id}", log_file)
    if metrics:
        r.add_get("/metrics", metrics_get)
        app.on_cleanup.append(_stop_metrics)
    statuspage.install(app, lambda: api.status())  # /, /favicon.ico, /v1/ws/status
    return app


# --- middlewares -----------------------------------------------------------------------------

def _errors(api: Api):
    @web.middleware
    async def middleware(request: web.Request, handler):
        try:
            return await handler(request)
        except RequestFailed as exc:
            return error(exc.status, str(exc))
        except web.HTTPRequestEntityTooLarge:
            return error(413, f"body over {MAX_BODY_BYTES} bytes")
        except web.HTTPException as exc:
            if exc.status < 400:
                raise
            return error(exc.status, exc.reason, {k: v for k, v in exc.headers.items() if k == "Allow"})
        except Exception:  # noqa: BLE001  (the error boundary of a request: counted, answered 500)
            api.failed("http")
            return error(500, "internal error (counted in the daemon's error counts)")
    return middleware


def _gate(token: str | None, guard: Guard):
    """The token (401), then the guard (421, 403, 415), then the handler; CORS on the answer."""
    expected = token.encode() if token else None

    @web.middleware
    async def middleware(request: web.Request, handler):
        token_ok = False
        if expected is not None:
            given = request.query.get("token", "")
            header = request.headers.get("Authorization", "")
            if header.startswith("Bearer "):
                given = header[7:].strip()
            token_ok = hmac.compare_digest(given.encode(), expected)
            if not token_ok and request.path != "/favicon.ico" and request.method != "OPTIONS":
                return error(401, "a bearer token is required", {"WWW-Authenticate": 'Bearer realm="gcsd"'})
        # a 404 or a 405 changes nothing; a preflight has no route of its own
        routed = request.match_info.http_exception is None or request.method == "OPTIONS"
        refusal = guard.check(request.method, request.headers, token_ok) if routed else None
        if refusal is not None:
            return error(refusal.status, refusal.text)
        if request.method == "OPTIONS":
            response = web.Response(status=204)
            response.headers["Access-Control-Allow-Methods"] = "GET, POST, PUT, OPTIONS"
            response.headers["Access-Control-Allow-Headers"] = "Authorization, Content-Type"
        else:
            response = await handler(request)
        if not response.prepared:  # a WebSocket or a file already sent its headers
            response.headers.update(guard.cors(request.method, request.headers,
                                               request.headers.get("Access-Control-Request-Method")))
        return response
    return middleware


# --- mavlink2rest ----------------------------------------------------------------------------

async def mavlink_get(request: web.Request) -> web.Response:
    path = request.match_info.get("path", "")
    parts = [p for p in path.split("/") if p]
    try:
        value = request.app[API].tree.document(parts)
    except KeyError:
        raise RequestFailed(404, f"nothing at /{path}") from None
    return _json(value)


async def mavlink_post(request: web.Request) -> web.Response:
    document = await read_json(request)
    _send(request.app[API], document)
    return web.Response(status=200)


def _send(api: Api, document: object) -> None:
    try:
        header, msg = parse_envelope(document)
    except UnknownMessage as exc:
        raise RequestFailed(404, str(exc)) from None
    except BadMessage as exc:
        raise RequestFailed(422 if ":" in str(exc) else 400, str(exc)) from None
    api.post(header, msg)


async def helper(request: web.Request) -> web.Response:
    try:
        return _json(template(request.query.get("name", "")))
    except UnknownMessage as exc:
        raise RequestFailed(404, str(exc)) from None


async def info(request: web.Request) -> web.Response:
    from gcsd import __version__

    return _json({"version": API_VERSION, "service": {
        "name": "gcsd", "version": __version__, "sha": __version__, "build_date": "", "authors": "gcsd"}})


async def websocket(request: web.Request) -> web.StreamResponse:
    api: Api = request.app[API]
    guard = request.app[GUARD]
    if len(api.hub.subscribers) >= MAX_WEBSOCKETS:
        raise RequestFailed(503, f"{MAX_WEBSOCKETS} WebSocket clients already; try again later")
    ids = {}
    for key, top in (("sysid", 255), ("compid", 255)):
        text = request.query.get(key)
        if text is not None:
            ids[key] = ascii_id(text)
            if ids[key] is None or ids[key] > top:
                raise RequestFailed(400, f"{key} must be a number from 0 to {top}")
    try:
        sub = api.hub.subscribe(request.query.get("filter", ".*"), **ids)
    except re.error as exc:
        raise RequestFailed(400, f"filter is not a regular expression: {exc}") from None
    ws = web.WebSocketResponse(heartbeat=30.0, max_msg_size=MAX_BODY_BYTES)
    try:
        await ws.prepare(request)
        sender = asyncio.create_task(_drain(sub, ws))
        try:
            async for frame in ws:
                if frame.type not in (WSMsgType.TEXT, WSMsgType.BINARY):
                    continue
                try:
                    if guard.read_only:
                        guard.count("read_only")
                        raise RequestFailed(403, READ_ONLY_TEXT)
                    _send(api, parse_json(frame.data))
                except RequestFailed as exc:
                    await ws.send_str(json.dumps({"error": str(exc)}))
        finally:
            sender.cancel()
    finally:
        api.hub.unsubscribe(sub)
    return ws


async def raw_websocket(request: web.Request) -> web.StreamResponse:
    find = getattr(request.app[API], "raw_channel", None)
    channel = find() if find is not None else None
    if channel is None:
        raise RequestFailed(404, "no websocket channel is configured")
    from gcsd.links.websocket import Access, serve

    guard = request.app[GUARD]
    return await serve(channel, request, Access(None, guard.read_only, guard.count))


async def _drain(sub, ws: web.WebSocketResponse) -> None:
    queue = sub.queue
    try:
        while not ws.closed:
            await ws.send_str(await queue.get())
    except ConnectionError:
        pass  # the client went away: the receive loop ends too


# --- gcsd's own ------------------------------------------------------------------------------

async def metrics_get(request: web.Request) -> web.Response:
    built = request.app[METRICS]
    if not built:  # prometheus_client is imported here, at the first scrape, not at start
        from gcsd.api.http.metrics import Metrics

        built.append(Metrics(request.app[API].status))
        built[0].start()
    body, content_type = built[0].exposition()
    response = web.Response(body=body)
    response.headers["Content-Type"] = content_type
    return response


async def _stop_metrics(app: web.Application) -> None:
    for metrics in app[METRICS]:
        metrics.stop()


async def status(request: web.Request) -> web.Response:
    return _json(request.app[API].status())


def _vehicle(request: web.Request) -> Vehicle:
    text = request.match_info["sysid"]
    sysid = ascii_id(text)
    vehicle = request.app[API].vehicle(sysid) if sysid is not None else None
    if vehicle is None:
        raise RequestFailed(404, f"no vehicle with sysid {text}")
    return vehicle


async def parameters(request: web.Request) -> web.Response:
    return _json(_vehicle(request).parameters())


async def parameter(request: web.Request) -> web.Response:
    name = request.match_info["name"]
    entry = _vehicle(request).parameter(name)
    if entry is None:
        raise RequestFailed(404, f"no parameter {name}")
    return _json(entry)


async def parameter_put(request: web.Request) -> web.Response:
    vehicle = _vehicle(request)
    name = request.match_info["name"]
    if vehicle.parameter(name) is None:
        raise RequestFailed(404, f"no parameter {name}")
    body = await read_json(request)
    value = body.get("value") if isinstance(body, dict) else None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or abs(value) > FLOAT32_MAX \
            or not math.isfinite(value):  # PARAM_SET carries a float32, whatever the parameter's type
        raise RequestFailed(422, 'expected {"value": a finite number within float32 range}')
    return _json(await vehicle.set_parameter(name, float(value)))


async def mission(request: web.Request) -> web.Response:
    return _json(_vehicle(request).mission())


async def mission_put(request: web.Request) -> web.Response:
    vehicle = _vehicle(request)
    document = await read_json(request)
    try:
        counts = vehicle.put_mission(document)
    except PlanError as exc:
        raise RequestFailed(422, str(exc)) from None
    return _json(counts)


async def mode(request: web.Request) -> web.Response:
    vehicle = _vehicle(request)
    body = await read_json(request)
    name = body.get("mode") if isinstance(body, dict) else None
    if not isinstance(name, str):
        raise RequestFailed(422, 'expected {"mode": NAME}')
    if name.upper() not in vehicle.mode_names():
        raise RequestFailed(422, f"unknown mode {name!r}; known: {', '.join(vehicle.mode_names())}")
    await vehicle.set_mode(name.upper())
    return _json({"mode": name.upper()})


async def _arm(request: web.Request, armed: bool) -> web.Response:
    vehicle = _vehicle(request)
    body = await read_json(request) if request.can_read_body else {}
    if not isinstance(body, dict):
        raise RequestFailed(422, "expected {}")
    await vehicle.arm(armed)
    return _json({"armed": armed})


async def arm(request: web.Request) -> web.Response:
    return await _arm(request, True)


async def disarm(request: web.Request) -> web.Response:
    return await _arm(request, False)


async def logs(request: web.Request) -> web.Response:
    return _json(request.app[API].logs())


async def log_file(request: web.Request) -> web.StreamResponse:
    path = request.app[API].log_file(request.match_info["id"], ascii_id(request.query.get("sysid", "")))
    if path is None:
        raise RequestFailed(404, f"no log {request.match_info['id']}")
    return web.FileResponse(path, headers={"Content-Type": "application/octet-stream"})
