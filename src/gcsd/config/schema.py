"""The configuration's schema: the frozen dataclasses a YAML file is read into, their defaults,
and the limits the reader checks against (config.py reads and validates; config_mqtt.py and
config_companion.py hold the mqtt channel's and the companion routing's parts).

Defaults that depend on other keys resolve in `__post_init__`: `vehicle.compid` (191 for a
companion, else 1), a serial channel's `bandwidth` (baud // 10); a channel's `streams` always
holds all ten streams (the given rates merged over DEFAULT_STREAM_RATES_HZ).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from gcsd.config.can import CanConfig
from gcsd.config.companion import ChannelFilter, RoutingConfig
from gcsd.config.http import HttpConfig
from gcsd.config.logs import FlightLogsConfig
from gcsd.config.mqtt import MqttConfig
from gcsd.wire.streams import STREAM_NAMES

DEFAULT_STREAM_RATES_HZ = {"raw_sens": 2, "ext_stat": 2, "rc_chan": 5, "raw_ctrl": 0, "position": 2,
                           "extra1": 5, "extra2": 5, "extra3": 2, "params": 10, "adsb": 0}
VEHICLE_TYPES = ("copter", "plane", "rover", "sub", "tracker", "blimp", "companion")
CHANNEL_TYPES = ("udp-server", "udp-client", "tcp-server", "tcp-client", "serial", "mqtt", "websocket")
CHANNEL_OPTIONS = ("no_forward", "no_stream_override", "unsigned_ok", "forward_bad_crc", "high_latency",
                   "sign_forwarded")
LOG_LEVELS = ("debug", "info", "warning", "error")
LOG_FORMATS = ("console", "json")

DEFAULT_FTP_MAX_FILE_BYTES = 64 * 1024 * 1024
MAX_FTP_FILE_BYTES = 0xFFFFFFFF  # FTP offsets are u32
MAX_CHANNELS = 10  # MAVLink channel slots: the SRn_* parameters have one digit, n = 0..9
LOCAL_TYPE = "local"  # the HTTP API's own channel (gcsd.api.http.local): built, never configured
MAX_STREAM_RATE_HZ = 50
MAX_SPEEDUP = 1000
COMPANION_COMPID = 191  # MAV_COMP_ID_ONBOARD_COMPUTER
SIGNING_KEY_HEX_CHARS = 64
MAX_MISSION_ITEMS = 65535  # MISSION_COUNT.count is a uint16
MIN_MISSION_RETRY_MS, MAX_MISSION_RETRY_MS = 50, 5000
DEFAULT_MAX_PEERS, MAX_MAX_PEERS = 8, 64  # ground stations one udp-server/tcp-server serves at once
MAX_CONFIG_BYTES = 1024 * 1024  # a configuration is a few KB; /dev/zero or a log file is refused
MAX_DEPTH = 32  # the schema needs 4; the composer recurses, so depth is checked before it runs
SERVER_TYPES = ("udp-server", "tcp-server")  # bind an address; one that is taken at start is fatal
NETWORK_TYPES = ("udp-server", "udp-client", "tcp-server", "tcp-client")  # have an address
DATAGRAM_TYPES = frozenset({"udp-server", "udp-client", "mqtt"})  # one frame per datagram, no flow control
SERIAL_CONTROL_PORTS = ("telem1", "telem2", "gps1", "gps2", *(f"serial{n}" for n in range(10)))


def mavlink_slot(types: Sequence[str], index: int) -> int | None:
    """The n of the SRn_* parameters of the daemon's channel `index` (`types`: every channel's
    type, in the daemon's order): its place among the MAVLink channels, so that SR0_ .. SR9_ are
    the configured and run-time channels whatever the position of the HTTP API's channel. That
    channel (type local) has none: it is no MAVLink link a ground station sets rates on, and its
    rates are the fixed defaults (DEFAULT_STREAM_RATES_HZ)."""
    if types[index] == LOCAL_TYPE:
        return None
    return sum(1 for t in types[:index] if t != LOCAL_TYPE)


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
    camera: bool = False  # a simulated MAVLink camera per vehicle (compid 100; gcsd.payloads.camera)
    gimbal: bool = False  # a simulated 3-axis gimbal, the autopilot its gimbal manager (gcsd.payloads.gimbal)

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
    retry_ms: int = 1000  # the longest wait before re-requesting an item (ArduPilot's fixed 1000 ms); see gcsd.vehicle.mission.rtt


@dataclass(frozen=True)
class FtpConfig:
    root: str = "ftp"
    max_file_bytes: int = DEFAULT_FTP_MAX_FILE_BYTES  # WriteFile/TruncateFile beyond this: FailErrno EFBIG


@dataclass(frozen=True)
class SigningConfig:
    key: bytes | None = None
    require: bool = False
    keys: tuple = ()  # NamedKey entries (config/authority.py): more keys, each with a role


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
    request_streams: int = 0  # Hz: REQUEST_DATA_STREAM to each autopilot learned here; 0: never
    role: str = "admin"  # what an unsigned peer here may do (config/authority.py): today's, everything

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
    flight_logs: FlightLogsConfig = field(default_factory=FlightLogsConfig)
    can: CanConfig = field(default_factory=CanConfig)
    http: HttpConfig = field(default_factory=HttpConfig)  # config_http.py
    metrics: bool = True  # GET /metrics on the HTTP port (gcsd.api.http.metrics)
    source: Source = field(default=Source(), compare=False, repr=False)


class ConfigError(Exception):
    """A configuration that must not start the daemon; `problems` lists every problem found."""

    def __init__(self, problems: list[str]) -> None:
        super().__init__("\n".join(problems))
        self.problems = list(problems)
