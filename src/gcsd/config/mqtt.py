"""The mqtt channel's configuration keys (SPEC.md "Fleet scale"), read by config.py's reader.

    - name: fleet
      type: mqtt
      broker: mqtt://127.0.0.1:1883   # mqtts://HOST[:PORT] for TLS (port 8883 by default)
      topic: gcsd/fleet1              # prefix of every topic; no wildcards, no empty levels
      role: vehicle                   # vehicle | ground
      sysids: all                     # role ground only: all, a sysid, "A-B", or a list of those
      username: null                  # with password_file: a file whose first line is the password
      password_file: null
      client_id: null                 # null: gcsd-<12 random hex digits>, new for each process
      ca_file: null                   # mqtts only: CA bundle (null: the system's trust store)
      cert_file: null                 # mqtts only: client certificate (and key_file) for brokers
      key_file: null                  #   that authenticate clients by certificate (AWS IoT)

Every key is optional. Decisions: credentials never go in the URL (it is logged) and the
password never in the configuration (it is shown by `check-config` errors and kept in memory
as plain text): a file, readable only by the daemon's user, as systemd credentials provide.
The password file is read at each connect, not here, so check-config does not need the secret
and a rotated password is used at the next reconnect. Keys that only make sense together are
checked together (cert_file needs mqtts, key_file needs cert_file, password_file needs username,
sysids needs role ground), so a half-configured TLS setup cannot silently connect in clear.
This module imports no MQTT library: validating a file does not need one.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

MQTT_KEYS = ("broker", "topic", "role", "sysids", "username", "password_file", "client_id",
             "ca_file", "cert_file", "key_file")
ROLES = ("vehicle", "ground")
DEFAULT_PORTS = {"mqtt": 1883, "mqtts": 8883}
DEFAULT_BROKER = "mqtt://127.0.0.1:1883"
DEFAULT_TOPIC = "gcsd"
ROUTES_PER_MQTT_CHANNEL = 4 * 255  # a fleet: up to 255 systems of a few components each
_URL_FORM = "expected mqtt://HOST[:PORT] or mqtts://HOST[:PORT]"


@dataclass(frozen=True)
class MqttConfig:
    broker: str = DEFAULT_BROKER  # as written, for logs
    tls: bool = False
    host: str = "127.0.0.1"
    port: int = 1883
    topic: str = DEFAULT_TOPIC
    role: str = "vehicle"
    sysids: frozenset[int] | None = None  # role ground: None takes every system
    username: str | None = None
    password_file: str | None = None
    client_id: str | None = None
    ca_file: str | None = None
    cert_file: str | None = None
    key_file: str | None = None


def parse_broker(url: str) -> tuple[bool, str, int]:
    """'mqtt://host[:port]' or 'mqtts://host[:port]' -> (tls, host, port); ValueError if not."""
    scheme, sep, rest = url.partition("://")
    if not sep or scheme not in DEFAULT_PORTS:
        raise ValueError(_URL_FORM)
    rest = rest.removesuffix("/")
    if "@" in rest:
        raise ValueError(f"{_URL_FORM}; credentials go in username and password_file, not the URL")
    if not rest or "/" in rest or any(c.isspace() or ord(c) < 32 for c in rest):
        raise ValueError(_URL_FORM)
    if rest.startswith("["):  # [IPv6] or [IPv6]:PORT
        host, _, tail = rest[1:].partition("]")
        if tail and not tail.startswith(":"):
            raise ValueError(_URL_FORM)
        port_text = tail[1:]
    elif rest.count(":") > 1:
        raise ValueError(f"{_URL_FORM} (an IPv6 address goes in brackets: mqtt://[::1]:1883)")
    else:
        host, _, port_text = rest.partition(":")
    if not host or (port_text and not (port_text.isascii() and port_text.isdigit())) or rest.endswith(":"):
        raise ValueError(_URL_FORM)
    port = int(port_text) if port_text else DEFAULT_PORTS[scheme]
    if not 1 <= port <= 65535:
        raise ValueError(f"port must be 1..65535, got {port}")
    return scheme == "mqtts", host, port


def topic_problem(topic: str) -> str | None:
    """Why a topic prefix cannot be used, or None."""
    if any(c in topic for c in "+#\0"):
        return "a topic prefix may not contain the wildcards + and # (or NUL)"
    if topic.startswith("/") or topic.endswith("/") or "//" in topic:
        return f"expected a topic prefix such as gcsd/fleet1 (no empty levels), got {topic!r}"
    if len(topic.encode()) > 1000:
        return "a topic prefix longer than 1000 bytes"
    return None


def parse_sysid_item(value) -> range | None:
    """One item of `sysids`: an integer 1..255 or the text "A-B" (1 <= A <= B <= 255)."""
    if type(value) is int:
        return range(value, value + 1) if 1 <= value <= 255 else None
    if not isinstance(value, str):
        return None
    low, sep, high = value.partition("-")
    low, high = low.strip(), high.strip()
    if not sep or not (low.isascii() and low.isdigit() and high.isascii() and high.isdigit()):
        return None
    a, b = int(low), int(high)
    return range(a, b + 1) if 1 <= a <= b <= 255 else None


def read_mqtt(r, c, channel_type: str) -> MqttConfig | None:
    """The mqtt keys of one channel section (`r` is config.py's _Reader, `c` the section)."""
    present = [key for key in MQTT_KEYS if key in c]
    if channel_type != "mqtt":
        for key in present:
            if key == "role":  # the authority role there (config/authority.py)
                continue
            r.problem(c[key], "only used by mqtt channels")
        return None
    for key in ("address", "device", "baud"):
        if key in c:
            r.problem(c[key], "not used by mqtt channels (the broker is `broker: mqtt://HOST:PORT`)")
    broker = r.text(c["broker"], DEFAULT_BROKER)
    try:
        tls, host, port = parse_broker(broker)
    except ValueError as exc:
        r.problem(c["broker"], f"{exc}, got {broker!r}")
        broker, (tls, host, port) = DEFAULT_BROKER, parse_broker(DEFAULT_BROKER)
    topic = r.text(c["topic"], DEFAULT_TOPIC)
    problem = topic_problem(topic)
    if problem:
        r.problem(c["topic"], problem)
        topic = DEFAULT_TOPIC
    role = r.choice(c["role"], "vehicle", ROLES)
    sysids = _sysids(r, c["sysids"])
    if "sysids" in c and role != "ground":
        r.problem(c["sysids"], "only used by role ground (a vehicle-side channel serves its own systems)")
    files = {key: _file(r, c[key]) for key in ("password_file", "ca_file", "cert_file", "key_file")}
    username = r.text(c["username"], None, nullable=True)
    if files["password_file"] is not None and username is None:
        r.problem(c["password_file"], "needs username")
    for key in ("ca_file", "cert_file", "key_file"):
        if files[key] is not None and not tls:
            r.problem(c[key], "only used with an mqtts:// broker")
    if files["key_file"] is not None and files["cert_file"] is None:
        r.problem(c["key_file"], "needs cert_file")
    return MqttConfig(broker=broker, tls=tls, host=host, port=port, topic=topic, role=role, sysids=sysids,
                      username=username, client_id=r.text(c["client_id"], None, nullable=True), **files)


def _file(r, f) -> str | None:
    value = r.text(f, None, nullable=True)
    if value is not None and "\0" in value:
        r.problem(f, "a path cannot contain a NUL byte")
        return None
    return value


def _sysids(r, f) -> frozenset[int] | None:
    """`all`, one item, or a list of items -> the set of sysids (None: all)."""
    if f.node is None:
        return None
    wanted = 'all, a sysid 1..255, a range "A-B", or a list of those'
    value = r.scalar(f.node)
    if value == "all":
        return None
    items = r.sequence(f) if getattr(f.node, "id", "") == "sequence" else [f]
    if not items:
        return r.reject(f, wanted, None)
    out: set[int] = set()
    for item in items:
        got = parse_sysid_item(r.scalar(item.node))
        if got is None:
            r.reject(item, wanted, None)
        else:
            out.update(got)
    return frozenset(out) if out else None


def route_capacity(channel_types: Iterable[str], base: int) -> int:
    """Routes a process needs: ArduPilot's table (`base`), plus room for a whole fleet per mqtt
    channel. A ground-side instance learns every vehicle of the fleet on its mqtt channel, and
    with ArduPilot's 20 routes the 21st vehicle could not be reached until a route went stale."""
    return base + ROUTES_PER_MQTT_CHANNEL * sum(1 for t in channel_types if t == "mqtt")
