"""Who may change state over HTTP: the checks a request passes before any handler (SPEC.md
"Authority", its HTTP part), and the answers that never say `*` to a state-changing request.

A browser lets any page send a "simple request" (POST with `Content-Type: text/plain`, no
preflight) to 127.0.0.1, and a DNS-rebinding page reaches it under its own host name. So, for a
request that changes state (POST, PUT, DELETE, PATCH) and for every WebSocket handshake:

- `Host` must name the listening address, `localhost`, `127.0.0.1` or `::1` (any IP literal when
  the API listens on a wildcard address: a rebinding page always has a DNS name): else 421
  (`host`). Reads are held to it too: a rebinding page reads the vehicle's position otherwise.
- `Origin`, when there is one, must be the page's own (the request's own `Host`, allowed as
  above): else 403 (`origin`). No `Origin` is curl, a script, a ground station.
- a state-changing request must say `Content-Type: application/json` (no browser sends that
  cross-origin without a preflight, which a foreign origin fails): else 415 (`content_type`).
- `read_only` (signing.require true and no http.token_file: a vehicle that demands signed
  MAVLink is not armed by an unauthenticated local request): 403 (`read_only`); the WebSocket
  is opened for receiving and answers each message sent on it with `{"error"}`.

A request that carries the right token (http.token_file) is the token holder's: its Host and
Origin are not checked (a LAN client names the companion as it likes; no page can forge the
token). CORS: reads answer `Access-Control-Allow-Origin: *` (mavlink2rest's, for dashboards);
a state-changing request and its preflight get the allowed origin back and `Vary: Origin`,
never `*`; a preflight from a foreign origin is 403. Every refusal is counted by reason
(`refused`, `gcsd status` as http_refused). Pure: no sockets, no clock.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Callable, Mapping
from dataclasses import dataclass

STATE_CHANGING = frozenset({"POST", "PUT", "DELETE", "PATCH"})
LOCAL_HOSTS = frozenset({"localhost", "127.0.0.1", "::1"})
WILDCARDS = frozenset({"", "0.0.0.0", "::"})
READ_ONLY_TEXT = "the API is read-only: signing.require is true and http.token_file is not set"
REASONS = ("host", "origin", "content_type", "read_only", "connections", "idle_replaced", "body_timeout")


@dataclass(frozen=True, slots=True)
class Refusal:
    status: int
    reason: str
    text: str


def host_name(value: str) -> str:
    """The host of a Host header or of an origin's authority, lower case, IPv6 without brackets."""
    value = value.strip().lower()
    if value.startswith("["):
        end = value.find("]")
        return value[1:end] if end > 0 else value
    if value.count(":") == 1:
        return value.split(":", 1)[0]
    return value


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


class Guard:
    def __init__(self, bound: Callable[[], tuple[str, int] | None], read_only: bool = False,
                 token: bool = False) -> None:
        self._bound = bound  # the listening address (None while not listening)
        self.read_only = read_only
        self.token = token
        self.refused: dict[str, int] = {}

    def count(self, reason: str) -> None:
        self.refused[reason] = self.refused.get(reason, 0) + 1

    def host_allowed(self, host: str) -> bool:
        name = host_name(host)
        if name in LOCAL_HOSTS:
            return True
        bound = self._bound()
        if bound is None:
            return False
        listening = host_name(bound[0])
        return name == listening or (listening in WILDCARDS and _is_ip(name))

    def origin_allowed(self, origin: str, host: str) -> bool:
        """The page's own origin: http://HOST exactly as the request names itself."""
        scheme, sep, authority = origin.partition("://")
        return (sep == "://" and scheme.lower() in ("http", "https") and authority.lower() == host.strip().lower()
                and self.host_allowed(host))

    def check(self, method: str, headers: Mapping[str, str], token_ok: bool = False) -> Refusal | None:
        """The refusal for a request, or None; counted. `token_ok`: it carried the right token."""
        websocket = headers.get("Upgrade", "").lower() == "websocket"
        changing = method in STATE_CHANGING
        preflight = headers.get("Access-Control-Request-Method", "").upper() if method == "OPTIONS" else ""
        trusted = token_ok or (method == "OPTIONS" and self.token)  # a preflight never carries the token
        host = headers.get("Host")
        refusal = None
        if not trusted and host is not None and not self.host_allowed(host):
            refusal = Refusal(421, "host", f"Host {host!r} is not this API's address (localhost, 127.0.0.1 "
                                           "or the listening address)")
        elif not trusted and (changing or websocket or preflight in STATE_CHANGING) and not self._origin_ok(headers):
            refusal = Refusal(403, "origin", f"Origin {headers.get('Origin')!r} may not use this API "
                                             "(only the page's own origin)")
        elif changing and self.read_only and not token_ok:
            refusal = Refusal(403, "read_only", READ_ONLY_TEXT)
        elif changing and _mimetype(headers.get("Content-Type", "")) != "application/json":
            refusal = Refusal(415, "content_type", "a request that changes state must be Content-Type: "
                                                   "application/json")
        if refusal is not None:
            self.count(refusal.reason)
        return refusal

    def _origin_ok(self, headers: Mapping[str, str]) -> bool:
        origin = headers.get("Origin")
        return origin is None or self.origin_allowed(origin, headers.get("Host", ""))

    def cors(self, method: str, headers: Mapping[str, str], preflight_method: str | None) -> dict[str, str]:
        """The CORS headers of an answer: `*` for reads; the allowed origin for the rest."""
        changing = method in STATE_CHANGING or (preflight_method or "").upper() in STATE_CHANGING
        if not changing:
            return {"Access-Control-Allow-Origin": "*"}
        origin = headers.get("Origin")
        if origin is None:
            return {"Vary": "Origin"}
        return {"Access-Control-Allow-Origin": origin, "Vary": "Origin"}


def _mimetype(value: str) -> str:
    return value.split(";", 1)[0].strip().lower()
