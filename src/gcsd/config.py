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
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path, PurePath
from types import MappingProxyType

import yaml
from yaml.nodes import MappingNode, SequenceNode

from .config_companion import (
    COMPANION_KEYS,
    ChannelFilter,
    RoutingConfig,
    read_bauds,
    read_companion,
    read_routing,
)
from .config_mqtt import MQTT_KEYS, MqttConfig, read_mqtt
from .config_reader import Field, Reader, Section, describe, is_null, line_of

STREAM_NAMES = ("raw_sens", "ext_stat", "rc_chan", "raw_ctrl", "position",
                "extra1", "extra2", "extra3", "params", "adsb")
DEFAULT_STREAM_RATES_HZ = {"raw_sens": 2, "ext_stat": 2, "rc_chan": 5, "raw_ctrl": 0, "position": 2,
                           "extra1": 5, "extra2": 5, "extra3": 2, "params": 10, "adsb": 0}
VEHICLE_TYPES = ("copter", "plane", "rover", "sub", "tracker", "blimp", "companion")
CHANNEL_TYPES = ("udp-server", "udp-client", "tcp-server", "tcp-client", "serial", "mqtt")
CHANNEL_OPTIONS = ("no_forward", "no_stream_override", "unsigned_ok", "forward_bad_crc", "high_latency",
                   "sign_forwarded")
LOG_LEVELS = ("debug", "info", "warning", "error")
LOG_FORMATS = ("console", "json")

DEFAULT_FTP_MAX_FILE_BYTES = 64 * 1024 * 1024
MAX_FTP_FILE_BYTES = 0xFFFFFFFF  # FTP offsets are u32
MAX_CHANNELS = 10  # the SRn_* parameters have one digit, n = 0..9
MAX_STREAM_RATE_HZ = 50
MAX_SPEEDUP = 1000
COMPANION_COMPID = 191  # MAV_COMP_ID_ONBOARD_COMPUTER
SIGNING_KEY_HEX_CHARS = 64
MAX_MISSION_ITEMS = 65535  # MISSION_COUNT.count is a uint16
MIN_MISSION_RETRY_MS, MAX_MISSION_RETRY_MS = 50, 5000
DEFAULT_MAX_PEERS, MAX_MAX_PEERS = 8, 64  # ground stations one udp-server/tcp-server serves at once
MAX_CONFIG_BYTES = 1024 * 1024  # a configuration is a few KB; /dev/zero or a log file is refused
MAX_DEPTH = 32  # the schema needs 4; the composer recurses, so depth is checked before it runs
_SERVER_TYPES = ("udp-server", "tcp-server")
_WILDCARD_HOSTS = ("0.0.0.0", "::", "*")


@dataclass(frozen=True)
class Home:
    lat: float = -35.363262
    lon: float = 149.165237
    alt: float = 584.0


@dataclass(frozen=True)
class VehicleConfig:
    type: str = "copter"
    sysid: int = 1
    compid: int | None = None  # None resolves to COMPANION_COMPID for a companion, else 1
    count: int = 1
    home: Home = Home()
    speedup: float = 1.0

    def __post_init__(self) -> None:
        if self.compid is None:
            object.__setattr__(self, "compid", COMPANION_COMPID if self.type == "companion" else 1)


@dataclass(frozen=True)
class GcsConfig:
    sysid: int = 255
    enforce_sysid: bool = False


@dataclass(frozen=True)
class MissionConfig:
    max_items: int = 700  # mission items, home (item 0) included
    max_fence: int = 100
    max_rally: int = 50
    retry_ms: int = 1000  # the longest wait before re-requesting an item (ArduPilot's fixed 1000 ms); see gcsd.rtt


@dataclass(frozen=True)
class FtpConfig:
    root: str = "ftp"
    max_file_bytes: int = DEFAULT_FTP_MAX_FILE_BYTES  # WriteFile/TruncateFile beyond this: FailErrno EFBIG


@dataclass(frozen=True)
class SigningConfig:
    key: bytes | None = None
    require: bool = False


@dataclass(frozen=True)
class ChannelConfig:
    name: str
    type: str
    address: tuple[str, int] | None = None  # udp and tcp types
    device: str | None = None  # serial
    baud: int = 115200
    mavlink: int = 2
    streams: Mapping[str, float] = field(default_factory=dict)  # Hz, merged over the defaults
    options: frozenset[str] = frozenset()
    private: bool = False
    bandwidth: int | None = None  # bytes/s; None is unlimited, except serial: it resolves to baud // 10
    max_peers: int = DEFAULT_MAX_PEERS  # udp-server/tcp-server: ground stations served at once
    broadcast: bool = False  # udp-client: send to the (broadcast) address until a station answers (discovery.py)
    mqtt: MqttConfig | None = None  # type mqtt: broker, topic, role, ... (config_mqtt.py)
    # companion routing (config_companion.py)
    bauds: tuple[int, ...] = ()  # serial: the bauds tried in turn until a good frame; () is (baud,)
    group: str | None = None  # channels of one group are redundant links to the same systems
    filter: ChannelFilter = field(default_factory=ChannelFilter)
    rate_limits: Mapping[int, float] = field(default_factory=dict)  # msgid -> Hz on this channel's output
    request_streams: float = 0.0  # Hz: REQUEST_DATA_STREAM to each autopilot learned here; 0: never

    def __post_init__(self) -> None:
        if not self.bauds:
            object.__setattr__(self, "bauds", (self.baud,))
        object.__setattr__(self, "rate_limits", MappingProxyType(dict(self.rate_limits)))
        # Any mapping given is merged over the defaults and frozen, so streams always has all ten.
        object.__setattr__(self, "streams", MappingProxyType(
            {name: float(self.streams.get(name, DEFAULT_STREAM_RATES_HZ[name])) for name in STREAM_NAMES}))
        if self.bandwidth is None and self.type == "serial":
            object.__setattr__(self, "bandwidth", self.baud // 10)


@dataclass(frozen=True)
class SerialControlPort:
    """A device a ground station may reach with SERIAL_CONTROL (REFERENCE.md section 11)."""

    port: str  # SERIAL_CONTROL_PORTS: telem1, telem2, gps1, gps2, serial0..serial9
    device: str
    baud: int = 115200


@dataclass(frozen=True)
class LogConfig:
    level: str = "info"
    format: str = "console"
    tlog: str | None = None


@dataclass(frozen=True)
class Source:
    """Where a configuration came from: the file and the line of each key path (for messages)."""

    file: str | None = None  # None: the built-in default
    lines: Mapping[str, int] = field(default_factory=lambda: MappingProxyType({}))

    def where(self, path: str) -> str:
        """``FILE:LINE: key.path`` for a key of this configuration (the nearest enclosing key's
        line when the key itself is absent: it took its default)."""
        if self.file is None:
            return f"(built-in default configuration): {path}"
        probe = path
        while probe and probe not in self.lines:
            probe = probe.rpartition(".")[0] if "." in probe else probe.rpartition("[")[0]
        return f"{self.file}:{self.lines.get(probe, 1)}: {path}"


@dataclass(frozen=True)
class Config:
    vehicle: VehicleConfig = VehicleConfig()
    state_dir: Path = Path("./gcsd-state")
    params_file: Path | None = None
    gcs: GcsConfig = GcsConfig()
    mission: MissionConfig = MissionConfig()
    ftp: FtpConfig = FtpConfig()
    signing: SigningConfig = SigningConfig()
    channels: tuple[ChannelConfig, ...] = (  # config/gcsd.yaml says why (README "Connect a ground station")
        ChannelConfig(name="lan", type="udp-client", address=("255.255.255.255", 14550), broadcast=True),
        ChannelConfig(name="gcs", type="udp-server", address=("0.0.0.0", 14551)),
    )
    log: LogConfig = LogConfig()
    serial_control: tuple[SerialControlPort, ...] = ()
    routing: RoutingConfig = field(default_factory=RoutingConfig)
    source: Source = field(default=Source(), compare=False, repr=False)


class ConfigError(Exception):
    """A configuration that must not start the daemon; `problems` lists every problem found."""

    def __init__(self, problems: list[str]) -> None:
        super().__init__("\n".join(problems))
        self.problems = list(problems)


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
             "serial_control", "routing")
SERIAL_CONTROL_PORTS = ("telem1", "telem2", "gps1", "gps2", *(f"serial{n}" for n in range(10)))
_VEHICLE_KEYS = ("type", "sysid", "compid", "count", "home", "speedup")
_MISSION_KEYS = ("max_items", "max_fence", "max_rally", "retry_ms")
_CHANNEL_KEYS = ("name", "type", "address", "device", "baud", "mavlink", "streams", "options",
                 "private", "bandwidth", "max_peers", "broadcast", *MQTT_KEYS, *COMPANION_KEYS)
_NETWORK_TYPES = tuple(t for t in CHANNEL_TYPES if t not in ("serial", "mqtt"))
_SIGNING_KEY = re.compile(f"[0-9a-fA-F]{{{SIGNING_KEY_HEX_CHARS}}}")
_ADDRESS = re.compile(r"(?:\[(?P<ipv6>[^\]\x00-\x1f]+)\]|(?P<host>[^:\s\[\]\x00-\x1f]+)):(?P<port>[0-9]{1,5})",
                      re.ASCII)


def _config(r: Reader, top: Section) -> Config:
    ftp = r.section(top["ftp"], ("root", "max_file_bytes"))
    log = r.section(top["log"], ("level", "format", "tlog"))
    gcs = r.section(top["gcs"], ("sysid", "enforce_sysid"))
    params_file = r.path(top["params_file"], None, nullable=True)
    channels = _channels(r, top["channels"])
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
        signing=_signing(r, r.section(top["signing"], ("key", "require"))),
        channels=channels,
        log=LogConfig(level=r.choice(log["level"], "info", LOG_LEVELS),
                      format=r.choice(log["format"], "console", LOG_FORMATS),
                      tlog=r.path(log["tlog"], None, nullable=True)),
        serial_control=_serial_control(r, top["serial_control"], channels),
        routing=read_routing(r, top["routing"]),
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
                         require=r.boolean(s["require"], False))


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
    if a.type in _SERVER_TYPES and b.type in _SERVER_TYPES:
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
    serial, network = channel_type == "serial", channel_type in _NETWORK_TYPES
    address = device = None
    if "address" in c and serial:
        r.problem(c["address"], "not used by serial channels (use device and baud)")
    elif "address" in c:
        address = _address(r, c["address"])
    elif network:
        r.problem(c["address"], f"required for type {channel_type}")
    for key in ("device", "baud"):
        if key in c and network:
            r.problem(c[key], "only used by serial channels")
    if "device" in c:
        device = r.path(c["device"], None)
    elif serial:
        r.problem(c["device"], "required for type serial")
    if "max_peers" in c and channel_type not in _SERVER_TYPES:
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
