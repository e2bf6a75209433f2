"""Configuration: a YAML file validated into frozen dataclasses.

The text is *composed* into PyYAML nodes, not loaded, so every value keeps its line. A `Reader`
walks the nodes section by section; each check returns the value, or records a problem
``FILE:LINE: key.path: what is wrong`` and returns the key's default, and the walk goes on. One
pass finds every problem; `ConfigError` carries them all, sorted by line.

Every key is optional. Unknown and duplicate keys are problems (the closest known key is
suggested). A section or list that is null takes its default; a null scalar is a problem unless
its default is null. Text values (names, addresses, paths, the key) are read from their source
text, so ``address: 1:30`` is not YAML 1.1's sexagesimal 90. Defaults that depend on other keys
(``vehicle.compid``: 191 for a companion, else 1; a serial channel's ``bandwidth``: baud // 10)
are resolved by the dataclasses themselves. Relative paths stay relative to the working directory
(the daemon's, which is what a user who types ``gcsd -c sitl/plane.yaml`` expects; `gcsd status`
finds a daemon started elsewhere through its runtime registration, see control.py).

Hostile or broken files are refused, never a traceback: at most MAX_CONFIG_BYTES are read,
nesting deeper than MAX_DEPTH is refused (checked on the event stream, before the recursive
composer runs), aliases only ever reach the schema's few known keys, and a NUL byte in a path
is a problem. Two channels that would share a listening port or target (a UDP/TCP server
bound to the same or an overlapping address, two clients to the same address, two users of one
serial device) are refused: the second bind would fail or the first would go deaf.
`ftp.root` must be a directory *under* state_dir: "." would hand signing.key to any FTP client.

`Config.source` keeps the file name and the line of every key (not compared), so checks made
later against the filesystem (preflight.py) report ``FILE:LINE: key.path: what`` too.
"""

from __future__ import annotations

import os
import re
from dataclasses import replace
from pathlib import Path, PurePath
from types import MappingProxyType

import yaml
from yaml.nodes import MappingNode, SequenceNode

from gcsd.config.authority import read_channel_role, read_signing_keys
from gcsd.config.can import read_can
from gcsd.config.companion import (
    COMPANION_KEYS,
    read_bauds,
    read_companion,
    read_routing,
)
from gcsd.config.http import read_http
from gcsd.config.logs import read_flight_logs
from gcsd.config.mqtt import MQTT_KEYS, read_mqtt
from gcsd.config.reader import Field, Reader, Section, describe, is_null, line_of
from gcsd.config.schema import (  # noqa: F401  the schema, re-exported: `from gcsd.config import Config` works
    CHANNEL_OPTIONS,
    CHANNEL_TYPES,
    COMPANION_COMPID,
    DATAGRAM_TYPES,
    DEFAULT_FTP_MAX_FILE_BYTES,
    DEFAULT_MAX_PEERS,
    DEFAULT_STREAM_RATES_HZ,
    LOG_FORMATS,
    LOG_LEVELS,
    MAX_CHANNELS,
    MAX_CONFIG_BYTES,
    MAX_DEPTH,
    MAX_FTP_FILE_BYTES,
    MAX_MAX_PEERS,
    MAX_MISSION_ITEMS,
    MAX_MISSION_RETRY_MS,
    MAX_SPEEDUP,
    MAX_STREAM_RATE_HZ,
    MIN_MISSION_RETRY_MS,
    NETWORK_TYPES,
    SERIAL_CONTROL_PORTS,
    SERVER_TYPES,
    SIGNING_KEY_HEX_CHARS,
    VEHICLE_TYPES,
    ChannelConfig,
    Config,
    ConfigError,
    FtpConfig,
    GcsConfig,
    Home,
    LogConfig,
    MissionConfig,
    SerialControlPort,
    SigningConfig,
    Source,
    VehicleConfig,
)
from gcsd.wire.streams import STREAM_NAMES

_WILDCARD_HOSTS = ("0.0.0.0", "::", "*")


def default_config() -> Config:
    return Config()


def load_config(path: str | os.PathLike) -> Config:
    filename = os.fsdecode(path)
    try:
        with open(path, "rb") as file:  # bounded: /dev/zero or a huge file must not eat the memory
            raw = file.read(MAX_CONFIG_BYTES + 1)
    except (OSError, ValueError) as exc:  # ValueError: a NUL byte in the file name
        raise ConfigError([f"{filename}: cannot read: {getattr(exc, 'strerror', None) or exc}"]) from None
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError([f"{filename}:1: the file is larger than {MAX_CONFIG_BYTES} bytes"])
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise ConfigError([f"{filename}:{line}: invalid UTF-8 (byte {raw[exc.start]:#04x})"]) from None
    return parse_config(text, filename)


def parse_config(text: str, filename: str = "<config>") -> Config:
    try:
        _check_depth(text, filename)
        root = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        line = mark.line + 1 if mark else 1
        what = getattr(exc, "problem", None) or exc
        context = getattr(exc, "context", None)
        if context and str(what).startswith("but "):  # "expected a single document ..., but found another"
            what = f"{context}, {what}"
        raise ConfigError([f"{filename}:{line}: invalid YAML: {what}"]) from None
    except RecursionError:  # not reached after _check_depth; kept so no input can give a traceback
        raise ConfigError([f"{filename}:1: invalid YAML: nested too deeply"]) from None
    if root is not None and not is_null(root) and not isinstance(root, MappingNode):
        where = f"{filename}:{line_of(root)}"
        raise ConfigError([f"{where}: expected a mapping of sections at the top level, got {describe(root)}"])
    reader = Reader(filename)
    config = _config(reader, reader.section(Field(root, ""), _TOP_KEYS))
    if reader.problems:
        raise ConfigError([message for _, message in sorted(reader.problems, key=lambda p: p[0])])
    return replace(config, source=Source(filename, MappingProxyType(reader.lines)))


def _check_depth(text: str, filename: str) -> None:
    """Refuse nesting deeper than MAX_DEPTH from PyYAML's event stream (its parser is iterative;
    its composer, which builds the node tree, recurses and would overflow the stack)."""
    depth = 0
    for event in yaml.parse(text, Loader=yaml.SafeLoader):
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_DEPTH:
                line = event.start_mark.line + 1
                raise ConfigError([f"{filename}:{line}: invalid YAML: nested more than {MAX_DEPTH} levels deep"])
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1


# --- the schema, one function per section -------------------------------------------------------

_TOP_KEYS = ("vehicle", "state_dir", "params_file", "gcs", "mission", "ftp", "signing", "channels", "log",
             "serial_control", "routing", "flight_logs", "can", "http", "metrics")
_VEHICLE_KEYS = ("type", "sysid", "compid", "count", "home", "speedup", "camera", "gimbal")
_MISSION_KEYS = ("max_items", "max_fence", "max_rally", "retry_ms")
_CHANNEL_KEYS = ("name", "type", "address", "device", "baud", "mavlink", "streams", "options",
                 "private", "bandwidth", "max_peers", "broadcast", *MQTT_KEYS, *COMPANION_KEYS)
# `role` is one of MQTT_KEYS: on other channels it is the authority role (config/authority.py)
_SIGNING_KEY = re.compile(f"[0-9a-fA-F]{{{SIGNING_KEY_HEX_CHARS}}}")
_ADDRESS = re.compile(r"(?:\[(?P<ipv6>[^\]\x00-\x1f]+)\]|(?P<host>[^:\s\[\]\x00-\x1f]+)):(?P<port>[0-9]{1,5})",
                      re.ASCII)


def _config(r: Reader, top: Section) -> Config:
    ftp = r.section(top["ftp"], ("root", "max_file_bytes"))
    log = r.section(top["log"], ("level", "format", "tlog"))
    gcs = r.section(top["gcs"], ("sysid", "enforce_sysid"))
    params_file = r.path(top["params_file"], None, nullable=True)
    channels = _channels(r, top["channels"])
    signing = _signing(r, r.section(top["signing"], ("key", "require", "keys")))
    return Config(
        vehicle=_vehicle(r, r.section(top["vehicle"], _VEHICLE_KEYS)),
        state_dir=Path(r.path(top["state_dir"], "./gcsd-state")),
        params_file=None if params_file is None else Path(params_file),
        gcs=GcsConfig(sysid=r.integer(gcs["sysid"], 255, 1, 255),
                      enforce_sysid=r.boolean(gcs["enforce_sysid"], False)),
        mission=_mission(r, r.section(top["mission"], _MISSION_KEYS)),
        ftp=FtpConfig(root=_ftp_root(r, ftp["root"]),
                      max_file_bytes=r.integer(ftp["max_file_bytes"], DEFAULT_FTP_MAX_FILE_BYTES, 1,
                                               MAX_FTP_FILE_BYTES)),
        signing=signing,
        channels=channels,
        log=LogConfig(level=r.choice(log["level"], "info", LOG_LEVELS),
                      format=r.choice(log["format"], "console", LOG_FORMATS),
                      tlog=r.path(log["tlog"], None, nullable=True)),
        serial_control=_serial_control(r, top["serial_control"], channels),
        routing=read_routing(r, top["routing"]),
        flight_logs=read_flight_logs(r, top["flight_logs"], [c.name for c in channels]),
        can=read_can(r, top["can"]),
        http=read_http(r, top["http"], _address, signing.require),
        metrics=r.boolean(top["metrics"], True),
    )


def _serial_control(r: Reader, f: Field, channels: tuple[ChannelConfig, ...]) -> tuple[SerialControlPort, ...]:
    ports = []
    seen: set[str] = set()
    taken = {os.path.normpath(ch.device): i for i, ch in enumerate(channels) if ch.type == "serial" and ch.device}
    taken_by_port: dict[str, str] = {}
    for item in r.sequence(f):
        c = r.section(item, ("port", "device", "baud"))
        for key in ("port", "device"):
            if key not in c and isinstance(c.node, MappingNode):
                r.problem(c[key], "required for every serial_control entry")
        port = r.choice(c["port"], "", SERIAL_CONTROL_PORTS)
        if port and port in seen:
            r.problem(c["port"], f"duplicate serial_control port {port!r}")
        seen.add(port)
        device = r.path(c["device"], "")
        if device and os.path.normpath(device) in taken:
            index = taken[os.path.normpath(device)]
            r.problem(c["device"], f"serial device {device} is already used by channels[{index}] ({channels[index].name})")
        elif device and os.path.normpath(device) in taken_by_port:
            r.problem(c["device"], f"serial device {device} is already used by serial_control port "
                                   f"{taken_by_port[os.path.normpath(device)]}")
        elif device:
            taken_by_port[os.path.normpath(device)] = port
        ports.append(SerialControlPort(port=port, device=device, baud=r.integer(c["baud"], 115200, 1)))
    return tuple(p for p in ports if p.port and p.device)


def _vehicle(r: Reader, v: Section) -> VehicleConfig:
    vehicle_type = r.choice(v["type"], "copter", VEHICLE_TYPES)
    sysid = r.integer(v["sysid"], 1, 1, 255)
    compid = r.integer(v["compid"], None, 1, 255, nullable=True)
    count = r.integer(v["count"], 1, 1, 250)
    if sysid + count - 1 > 255:
        r.problem(v["count"] if "count" in v else v["sysid"],
                  f"the swarm's last sysid {sysid} + {count} - 1 = {sysid + count - 1} is above 255")
    home = r.section(v["home"], ("lat", "lon", "alt"))
    return VehicleConfig(
        type=vehicle_type, sysid=sysid, compid=compid, count=count,
        home=Home(lat=r.number(home["lat"], Home.lat, -90, 90),
                  lon=r.number(home["lon"], Home.lon, -180, 180),
                  alt=r.number(home["alt"], Home.alt, -1000, 100_000)),
        speedup=r.number(v["speedup"], 1.0, 0, MAX_SPEEDUP, low_open=True),
        camera=r.boolean(v["camera"], False), gimbal=r.boolean(v["gimbal"], False),
    )


def _mission(r: Reader, m: Section) -> MissionConfig:
    d = MissionConfig()
    return MissionConfig(
        max_items=r.integer(m["max_items"], d.max_items, 1, MAX_MISSION_ITEMS),
        max_fence=r.integer(m["max_fence"], d.max_fence, 1, MAX_MISSION_ITEMS),
        max_rally=r.integer(m["max_rally"], d.max_rally, 1, MAX_MISSION_ITEMS),
        retry_ms=r.integer(m["retry_ms"], d.retry_ms, MIN_MISSION_RETRY_MS, MAX_MISSION_RETRY_MS),
    )


def _ftp_root(r: Reader, f: Field) -> str:
    root = PurePath(r.path(f, "ftp"))
    if root.is_absolute() or ".." in root.parts:
        return r.reject(f, "a path relative to state_dir without '..'", "ftp")
    if not root.parts:  # ".", "./": FTP clients could read signing.key, mav.parm and the plans
        r.problem(f, "must be a directory under state_dir, not state_dir itself "
                     "(FTP clients could read the signing key and the saved parameters)")
        return "ftp"
    return str(root)


def _signing(r: Reader, s: Section) -> SigningConfig:
    key = r.text(s["key"], None, nullable=True)
    if key is not None and not _SIGNING_KEY.fullmatch(key):  # the message must not echo the key
        got = f"{len(key)} characters" if len(key) != SIGNING_KEY_HEX_CHARS else "other characters"
        r.problem(s["key"], f"expected {SIGNING_KEY_HEX_CHARS} hex characters or null, got {got}")
        key = None
    return SigningConfig(key=None if key is None else bytes.fromhex(key),
                         require=r.boolean(s["require"], False), keys=read_signing_keys(r, s["keys"]))


def _channels(r: Reader, f: Field) -> tuple[ChannelConfig, ...]:
    if f.node is None or is_null(f.node):
        return Config.channels
    if not isinstance(f.node, SequenceNode):
        return r.reject(f, "a list of channels", Config.channels)
    items = f.node.value
    if not 1 <= len(items) <= MAX_CHANNELS:
        r.problem(f, f"expected 1 to {MAX_CHANNELS} channels (SR0_ .. SR9_), got {len(items)}")
    first_index_by_name: dict[str, int] = {}
    channels = []
    sections: list[Section] = []
    for index, item in enumerate(items):
        r.lines.setdefault(f"{f.path}[{index}]", line_of(item))
        section = r.section(Field(item, f"{f.path}[{index}]"), _CHANNEL_KEYS)
        channel = _channel(r, section)
        if channel.name and channel.name in first_index_by_name:
            first = f"{f.path}[{first_index_by_name[channel.name]}]"
            r.problem(section["name"], f"duplicate channel name {channel.name!r} (also {first})")
        first_index_by_name.setdefault(channel.name, index)
        channels.append(channel)
        sections.append(section)
    _check_endpoints(r, channels, sections)
    return tuple(channels)


def _check_endpoints(r: Reader, channels: list[ChannelConfig], sections: list[Section]) -> None:
    """Two channels must not share a listening port, a target or a serial device: the second
    server's bind fails (or, with SO_REUSEADDR semantics, the first one goes deaf), two clients
    to one address send everything twice, two readers of one device split its bytes."""
    seen: list[tuple[int, ChannelConfig]] = []
    for index, (channel, section) in enumerate(zip(channels, sections)):
        for first, other in seen:
            clash = _clash(channel, other)
            if clash:
                key = "device" if channel.type == "serial" else "address"
                r.problem(section[key], f"{clash} channels[{first}] ({other.name})")
                break
        seen.append((index, channel))


def _clash(a: ChannelConfig, b: ChannelConfig) -> str | None:
    if a.type == "serial" or b.type == "serial":
        same = a.type == b.type == "serial" and a.device and os.path.normpath(a.device) == os.path.normpath(b.device)
        return f"serial device {a.device} is already used by" if same else None
    if a.address is None or b.address is None:
        return None
    (host_a, port_a), (host_b, port_b) = a.address, b.address
    if a.type in SERVER_TYPES and b.type in SERVER_TYPES:
        same_protocol = a.type[:3] == b.type[:3]  # a UDP and a TCP server may share a port number
        overlap = host_a == host_b or host_a in _WILDCARD_HOSTS or host_b in _WILDCARD_HOSTS
        if same_protocol and port_a == port_b != 0 and overlap:
            return f"{a.type[:3].upper()} port {port_a} on {host_a} is already bound by"
    elif a.type == b.type and a.address == b.address:
        return f"{host_a}:{port_a} is already the address of"
    return None


def _channel(r: Reader, c: Section) -> ChannelConfig:
    for key in ("name", "type"):
        if key not in c and isinstance(c.node, MappingNode):
            r.problem(c[key], "required for every channel")
    channel_type = r.choice(c["type"], "", CHANNEL_TYPES)
    serial, network = channel_type == "serial", channel_type in NETWORK_TYPES
    address = device = None
    if "address" in c and serial:
        r.problem(c["address"], "not used by serial channels (use device and baud)")
    elif "address" in c and not (channel_type == "websocket" and is_null(c["address"].node)):
        address = _address(r, c["address"])  # a websocket channel's: null or absent, the HTTP port only
    elif network:
        r.problem(c["address"], f"required for type {channel_type}")
    for key in ("device", "baud"):
        if key in c and network:
            r.problem(c[key], "only used by serial channels")
    if "device" in c:
        device = r.path(c["device"], None)
    elif serial:
        r.problem(c["device"], "required for type serial")
    if "max_peers" in c and channel_type not in SERVER_TYPES:
        r.problem(c["max_peers"], "only used by udp-server and tcp-server channels")
    if "broadcast" in c and channel_type != "udp-client":
        r.problem(c["broadcast"], "only used by udp-client channels")
    streams = r.section(c["streams"], STREAM_NAMES)
    options = frozenset(r.choice(o, "", CHANNEL_OPTIONS) for o in r.sequence(c["options"])) - {""}
    bauds = read_bauds(r, c["baud"])
    companion = read_companion(r, c, channel_type, address, options)
    return ChannelConfig(
        name=r.text(c["name"], ""), type=channel_type, address=address, device=device,
        baud=bauds[0], bauds=bauds, group=companion.group, filter=companion.filter,
        rate_limits=companion.rate_limits, request_streams=companion.request_streams,
        mavlink=r.integer(c["mavlink"], 2, 1, 2),
        streams={name: r.number(streams[name], float(DEFAULT_STREAM_RATES_HZ[name]), 0, MAX_STREAM_RATE_HZ)
                 for name in STREAM_NAMES},
        options=options,
        private=r.boolean(c["private"], False),
        bandwidth=r.integer(c["bandwidth"], None, 1, nullable=True),
        max_peers=r.integer(c["max_peers"], DEFAULT_MAX_PEERS, 1, MAX_MAX_PEERS),
        broadcast=r.boolean(c["broadcast"], False),
        mqtt=read_mqtt(r, c, channel_type),
        role=read_channel_role(r, c, channel_type),
    )


def _address(r: Reader, f: Field) -> tuple[str, int] | None:
    text = r.text(f, None)
    match = _ADDRESS.fullmatch(text) if text is not None else None
    if text is not None and match is None:
        r.problem(f, f"expected HOST:PORT, got {text!r}")
    elif match is not None and int(match["port"]) > 65535:
        r.problem(f, f"port must be 0..65535, got {int(match['port'])}")
    elif match is not None:
        return match["ipv6"] or match["host"], int(match["port"])
    return None
