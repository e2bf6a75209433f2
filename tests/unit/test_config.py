"""The configuration file: defaults, validation and the messages a user sees."""

from pathlib import Path
from textwrap import dedent

import pytest

from gcsd.config import (
    DEFAULT_STREAM_RATES_HZ,
    STREAM_NAMES,
    ChannelConfig,
    Config,
    ConfigError,
    Home,
    MissionConfig,
    default_config,
    load_config,
    parse_config,
)

DEFAULT_YAML = Path(__file__).resolve().parents[2] / "config" / "gcsd.yaml"
KEY_HEX = "00112233445566778899aabbccddeeff" * 2


def problems(text: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse_config(dedent(text), "gcsd.yaml")
    return caught.value.problems


def parse(text: str) -> Config:
    return parse_config(dedent(text), "gcsd.yaml")


# --- defaults ------------------------------------------------------------------------------------


def test_shipped_config_file_is_exactly_the_default():
    assert load_config(DEFAULT_YAML) == default_config()


def test_default_config_is_a_copter_broadcasting_to_14550_with_a_udp_server_on_14551():
    config = default_config()
    assert config == Config()
    assert (config.vehicle.type, config.vehicle.sysid, config.vehicle.compid) == ("copter", 1, 1)
    assert config.vehicle.home == Home(lat=-35.363262, lon=149.165237, alt=584.0)
    assert config.state_dir == Path("./gcsd-state")
    lan, gcs = config.channels
    assert (lan.name, lan.type, lan.address, lan.broadcast) == ("lan", "udp-client", ("255.255.255.255", 14550), True)
    assert (gcs.name, gcs.type, gcs.address, gcs.broadcast) == ("gcs", "udp-server", ("0.0.0.0", 14551), False)
    for channel in config.channels:
        assert dict(channel.streams) == DEFAULT_STREAM_RATES_HZ
        assert channel.bandwidth is None


@pytest.mark.parametrize("text", ["", "\n\n", "# only a comment\n  # and another\n", "---\n", "~\n"])
def test_empty_or_comment_only_file_is_the_default(text):
    assert parse(text) == default_config()


def test_null_sections_take_their_defaults():
    assert parse("vehicle:\ngcs:\nchannels:\nlog: null\n") == default_config()


# --- resolved defaults ---------------------------------------------------------------------------


@pytest.mark.parametrize(("vehicle_type", "compid"), [("companion", 191), ("copter", 1), ("plane", 1)])
def test_compid_defaults_to_191_for_a_companion_and_1_otherwise(vehicle_type, compid):
    assert parse(f"vehicle: {{type: {vehicle_type}}}").vehicle.compid == compid


def test_explicit_compid_wins_over_the_type_default():
    assert parse("vehicle: {type: companion, compid: 42}").vehicle.compid == 42


def test_serial_bandwidth_defaults_to_a_tenth_of_the_baud_rate():
    config = parse("""
        channels:
          - {name: radio, type: serial, device: /dev/ttyUSB0, baud: 57600}
          - {name: fc, type: serial, device: /dev/ttyAMA0}
          - {name: fast, type: serial, device: /dev/ttyS1, baud: 57600, bandwidth: 20000}
    """)
    assert [c.bandwidth for c in config.channels] == [5760, 11520, 20000]


def test_network_channel_bandwidth_defaults_to_unlimited():
    [channel] = parse("channels: [{name: a, type: tcp-server, address: '127.0.0.1:0'}]").channels
    assert channel.bandwidth is None


def test_streams_given_are_merged_over_the_defaults():
    [channel] = parse("""
        channels:
          - {name: gcs, type: udp-server, address: '0.0.0.0:14550', streams: {position: 10, adsb: 0.5}}
    """).channels
    assert dict(channel.streams) == {**DEFAULT_STREAM_RATES_HZ, "position": 10, "adsb": 0.5}
    assert tuple(channel.streams) == STREAM_NAMES


def test_streams_are_read_only():
    channel = default_config().channels[0]
    with pytest.raises(TypeError):
        channel.streams["position"] = 50  # type: ignore[index]


def test_channel_config_built_in_code_also_merges_streams_and_resolves_serial_bandwidth():
    channel = ChannelConfig(name="radio", type="serial", device="/dev/ttyUSB0", baud=57600,
                            streams={"rc_chan": 1})
    assert channel.bandwidth == 5760
    assert dict(channel.streams) == {**DEFAULT_STREAM_RATES_HZ, "rc_chan": 1}


# --- values that are read correctly ---------------------------------------------------------------


def test_a_full_configuration_is_read_into_the_dataclasses():
    config = parse(f"""
        vehicle: {{type: rover, sysid: 10, count: 5, home: {{lat: 48.5, lon: -1.25, alt: 12}}, speedup: 4}}
        state_dir: /var/lib/gcsd
        params_file: extra.parm
        gcs: {{sysid: 250, enforce_sysid: true}}
        ftp: {{root: files/ftp}}
        signing: {{key: {KEY_HEX}, require: true}}
        channels:
          - name: fc
            type: serial
            device: /dev/ttyAMA0
            baud: 921600
            mavlink: 1
            options: [no_forward, unsigned_ok, no_forward]
            private: true
          - {{name: ground, type: udp-client, address: '[::1]:14551'}}
        log: {{level: debug, format: json, tlog: flight.tlog}}
    """)
    assert (config.vehicle.type, config.vehicle.sysid, config.vehicle.count) == ("rover", 10, 5)
    assert config.vehicle.home == Home(lat=48.5, lon=-1.25, alt=12.0)
    assert config.vehicle.speedup == 4.0
    assert config.state_dir == Path("/var/lib/gcsd")
    assert config.params_file == Path("extra.parm")
    assert (config.gcs.sysid, config.gcs.enforce_sysid) == (250, True)
    assert config.ftp.root == "files/ftp"
    assert config.signing.key == bytes.fromhex(KEY_HEX) and config.signing.require
    fc, ground = config.channels
    assert (fc.device, fc.baud, fc.mavlink, fc.private) == ("/dev/ttyAMA0", 921600, 1, True)
    assert fc.options == frozenset({"no_forward", "unsigned_ok"})
    assert ground.address == ("::1", 14551)
    assert (config.log.level, config.log.format, config.log.tlog) == ("debug", "json", "flight.tlog")


def test_mission_limits_default_to_700_mission_100_fence_50_rally_items_and_1_s_retry():
    assert default_config().mission == MissionConfig(max_items=700, max_fence=100, max_rally=50, retry_ms=1000)


def test_mission_limits_are_read():
    config = parse("mission: {max_items: 1000, max_fence: 20, max_rally: 5, retry_ms: 250}\n")
    assert config.mission == MissionConfig(max_items=1000, max_fence=20, max_rally=5, retry_ms=250)


def test_ftp_write_limit_defaults_to_64_mib_and_is_read():
    assert default_config().ftp.max_file_bytes == 64 * 1024 * 1024
    assert parse("ftp: {max_file_bytes: 1000}\n").ftp.max_file_bytes == 1000


def test_relative_paths_are_kept_as_written():
    config = parse("state_dir: ./run/state\nparams_file: ../params/copter.parm\n")
    assert config.state_dir == Path("run/state")
    assert config.params_file == Path("../params/copter.parm")


@pytest.mark.parametrize(("text", "address"), [
    ("0.0.0.0:14550", ("0.0.0.0", 14550)),
    ("localhost:0", ("localhost", 0)),
    ("1:30", ("1", 30)),  # not YAML 1.1's sexagesimal integer 90
    ("'[fe80::1]:5760'", ("fe80::1", 5760)),
])
def test_address_is_host_and_port_read_from_the_source_text(text, address):
    assert parse(f"channels: [{{name: a, type: udp-client, address: {text}}}]").channels[0].address == address


def test_signing_key_made_only_of_digits_is_still_read_as_hex():
    key = "1234567890" * 6 + "1234"
    assert parse(f"signing: {{key: {key}}}").signing.key == bytes.fromhex(key)


def test_ten_channels_are_allowed():
    channels = "".join(f"  - {{name: c{i}, type: udp-server, address: '127.0.0.1:0'}}\n" for i in range(10))
    assert len(parse("channels:\n" + channels).channels) == 10


# --- problems: exactly what the user reads --------------------------------------------------------


BAD_CONFIGS = [
    ("vehicle:\n  sysdi: 2\n", "gcsd.yaml:2: vehicle.sysdi: unknown key; did you mean 'sysid'?"),
    ("chanels: []\n", "gcsd.yaml:1: chanels: unknown key; did you mean 'channels'?"),
    ("colour: red\n", ("gcsd.yaml:1: colour: unknown key (known keys: vehicle, state_dir, params_file, gcs, "
                       "mission, ftp, signing, channels, log, serial_control, routing, flight_logs, can, http, metrics)")),
    ("vehicle: {sysid: 1, sysid: 2}\n", "gcsd.yaml:1: vehicle.sysid: duplicate key"),
    ("vehicle: copter\n", "gcsd.yaml:1: vehicle: expected a mapping, got 'copter'"),
    ("vehicle: {type: coptr}\n", ("gcsd.yaml:1: vehicle.type: expected copter|plane|rover|sub|tracker|blimp|"
                                  "companion, got 'coptr'; did you mean 'copter'?")),
    ("vehicle: {sysid: 0}\n", "gcsd.yaml:1: vehicle.sysid: expected an integer 1..255, got 0"),
    ("vehicle: {sysid: 256}\n", "gcsd.yaml:1: vehicle.sysid: expected an integer 1..255, got 256"),
    ("vehicle: {sysid: one}\n", "gcsd.yaml:1: vehicle.sysid: expected an integer 1..255, got 'one'"),
    ("vehicle: {sysid: 1.5}\n", "gcsd.yaml:1: vehicle.sysid: expected an integer 1..255, got 1.5"),
    ("vehicle: {sysid: true}\n", "gcsd.yaml:1: vehicle.sysid: expected an integer 1..255, got true"),
    ("vehicle: {sysid: null}\n", "gcsd.yaml:1: vehicle.sysid: expected an integer 1..255, got null"),
    ("vehicle: {compid: 0}\n", "gcsd.yaml:1: vehicle.compid: expected an integer 1..255 or null, got 0"),
    ("vehicle: {count: 0}\n", "gcsd.yaml:1: vehicle.count: expected an integer 1..250, got 0"),
    ("vehicle: {count: 251}\n", "gcsd.yaml:1: vehicle.count: expected an integer 1..250, got 251"),
    ("vehicle:\n  sysid: 250\n  count: 7\n",
     "gcsd.yaml:3: vehicle.count: the swarm's last sysid 250 + 7 - 1 = 256 is above 255"),
    ("vehicle:\n  home:\n    lat: -90.5\n",
     "gcsd.yaml:3: vehicle.home.lat: expected a number -90..90, got -90.5"),
    ("vehicle: {home: {lon: 180.1}}\n",
     "gcsd.yaml:1: vehicle.home.lon: expected a number -180..180, got 180.1"),
    ("vehicle: {home: {lat: .nan}}\n", "gcsd.yaml:1: vehicle.home.lat: expected a number -90..90, got .nan"),
    ("vehicle: {home: {alt: high}}\n",
     "gcsd.yaml:1: vehicle.home.alt: expected a number -1000..100000, got 'high'"),
    ("vehicle: {home: [1, 2]}\n", "gcsd.yaml:1: vehicle.home: expected a mapping, got a list"),
    ("vehicle: {speedup: 0}\n", "gcsd.yaml:1: vehicle.speedup: expected a number > 0 and <= 1000, got 0"),
    ("vehicle: {speedup: 1001}\n",
     "gcsd.yaml:1: vehicle.speedup: expected a number > 0 and <= 1000, got 1001"),
    ("state_dir: ''\n", "gcsd.yaml:1: state_dir: expected a non-empty string, got ''"),
    ("state_dir: [a]\n", "gcsd.yaml:1: state_dir: expected a non-empty string, got a list"),
    ("params_file: {}\n", "gcsd.yaml:1: params_file: expected a non-empty string or null, got a mapping"),
    ("gcs: {sysid: 0}\n", "gcsd.yaml:1: gcs.sysid: expected an integer 1..255, got 0"),
    ("gcs: {enforce_sysid: 1}\n", "gcsd.yaml:1: gcs.enforce_sysid: expected true or false, got 1"),
    ("mission: {max_items: 0}\n", "gcsd.yaml:1: mission.max_items: expected an integer 1..65535, got 0"),
    ("mission: {max_fence: 65536}\n",
     "gcsd.yaml:1: mission.max_fence: expected an integer 1..65535, got 65536"),
    ("mission: {max_rally: many}\n", "gcsd.yaml:1: mission.max_rally: expected an integer 1..65535, got 'many'"),
    ("mission: {retry_ms: 10}\n", "gcsd.yaml:1: mission.retry_ms: expected an integer 50..5000, got 10"),
    ("mission: {max_item: 5}\n", "gcsd.yaml:1: mission.max_item: unknown key; did you mean 'max_items'?"),
    ("mission: 700\n", "gcsd.yaml:1: mission: expected a mapping, got 700"),
    ("ftp: {root: /srv/ftp}\n", ("gcsd.yaml:1: ftp.root: expected a path relative to state_dir without '..', "
                                 "got '/srv/ftp'")),
    ("ftp: {root: a/../../b}\n", ("gcsd.yaml:1: ftp.root: expected a path relative to state_dir without '..', "
                                  "got 'a/../../b'")),
    ("ftp: {max_file_bytes: 0}\n", "gcsd.yaml:1: ftp.max_file_bytes: expected an integer 1..4294967295, got 0"),
    ("ftp: {max_file_bytes: 4294967296}\n",
     "gcsd.yaml:1: ftp.max_file_bytes: expected an integer 1..4294967295, got 4294967296"),
    ("ftp: {max_file_bytes: 64M}\n", "gcsd.yaml:1: ftp.max_file_bytes: expected an integer 1..4294967295, got '64M'"),
    ("signing: {key: abcd}\n",
     "gcsd.yaml:1: signing.key: expected 64 hex characters or null, got 4 characters"),
    (f"signing: {{key: {'g' * 64}}}\n",
     "gcsd.yaml:1: signing.key: expected 64 hex characters or null, got other characters"),
    ("signing: {require: maybe}\n", "gcsd.yaml:1: signing.require: expected true or false, got 'maybe'"),
    ("channels: {name: gcs}\n", "gcsd.yaml:1: channels: expected a list of channels, got a mapping"),
    ("channels: []\n", "gcsd.yaml:1: channels: expected 1 to 10 channels (SR0_ .. SR9_), got 0"),
    ("channels:\n  - gcs\n", "gcsd.yaml:2: channels[0]: expected a mapping, got 'gcs'"),
    ("channels:\n  - type: udp-server\n    address: 0.0.0.0:1\n",
     "gcsd.yaml:2: channels[0].name: required for every channel"),
    ("channels:\n  - name: gcs\n", "gcsd.yaml:2: channels[0].type: required for every channel"),
    ("channels:\n  - name: ''\n    type: serial\n    device: /dev/ttyS0\n",
     "gcsd.yaml:2: channels[0].name: expected a non-empty string, got ''"),
    ("channels:\n  - name: gcs\n    type: udp\n    address: 0.0.0.0:1\n",
     "gcsd.yaml:3: channels[0].type: expected udp-server|udp-client|tcp-server|tcp-client|serial|mqtt|websocket, got 'udp'"),
    ("channels:\n  - name: gcs\n    type: tcp-server\n",
     "gcsd.yaml:2: channels[0].address: required for type tcp-server"),
    ("channels:\n  - name: gcs\n    type: udp-server\n    address: foo\n",
     "gcsd.yaml:4: channels[0].address: expected HOST:PORT, got 'foo'"),
    ("channels:\n  - name: gcs\n    type: udp-server\n    address: ':14550'\n",
     "gcsd.yaml:4: channels[0].address: expected HOST:PORT, got ':14550'"),
    ("channels:\n  - name: gcs\n    type: udp-server\n    address: 0.0.0.0:65536\n",
     "gcsd.yaml:4: channels[0].address: port must be 0..65535, got 65536"),
    ("channels:\n  - name: gcs\n    type: serial\n",
     "gcsd.yaml:2: channels[0].device: required for type serial"),
    ("channels:\n  - {name: fc, type: serial, device: /dev/ttyS0, address: '1.2.3.4:5'}\n",
     "gcsd.yaml:2: channels[0].address: not used by serial channels (use device and baud)"),
    ("channels:\n  - {name: gcs, type: udp-server, address: '0.0.0.0:1', device: /dev/ttyS0}\n",
     "gcsd.yaml:2: channels[0].device: only used by serial channels"),
    ("channels:\n  - {name: gcs, type: udp-server, address: '0.0.0.0:1', baud: 57600}\n",
     "gcsd.yaml:2: channels[0].baud: only used by serial channels"),
    ("channels:\n  - {name: fc, type: serial, device: /dev/ttyS0, baud: 0}\n",
     "gcsd.yaml:2: channels[0].baud: expected an integer >= 1, got 0"),
    ("channels:\n  - {name: fc, type: serial, device: /dev/ttyS0, mavlink: 3}\n",
     "gcsd.yaml:2: channels[0].mavlink: expected an integer 1..2, got 3"),
    ("channels:\n  - name: fc\n    type: serial\n    device: /dev/ttyS0\n    streams:\n      postion: 4\n",
     "gcsd.yaml:6: channels[0].streams.postion: unknown key; did you mean 'position'?"),
    ("channels:\n  - {name: fc, type: serial, device: /dev/ttyS0, streams: {extra1: 51}}\n",
     "gcsd.yaml:2: channels[0].streams.extra1: expected a number 0..50, got 51"),
    ("channels:\n  - {name: fc, type: serial, device: /dev/ttyS0, streams: {extra1: -1}}\n",
     "gcsd.yaml:2: channels[0].streams.extra1: expected a number 0..50, got -1"),
    ("channels:\n  - {name: fc, type: serial, device: /dev/ttyS0, options: [no_fwd]}\n",
     ("gcsd.yaml:2: channels[0].options[0]: expected "
      "no_forward|no_stream_override|unsigned_ok|forward_bad_crc|high_latency|sign_forwarded, "
      "got 'no_fwd'; did you mean 'no_forward'?")),
    ("channels:\n  - {name: fc, type: serial, device: /dev/ttyS0, options: no_forward}\n",
     "gcsd.yaml:2: channels[0].options: expected a list, got 'no_forward'"),
    ("channels:\n  - {name: fc, type: serial, device: /dev/ttyS0, private: no thanks}\n",
     "gcsd.yaml:2: channels[0].private: expected true or false, got 'no thanks'"),
    ("channels:\n  - {name: fc, type: serial, device: /dev/ttyS0, bandwidth: 0}\n",
     "gcsd.yaml:2: channels[0].bandwidth: expected an integer >= 1 or null, got 0"),
    ("channels:\n  - {name: fc, type: serial, device: /dev/ttyS0, bandwidth: 1e4}\n",
     "gcsd.yaml:2: channels[0].bandwidth: expected an integer >= 1 or null, got '1e4'"),
    ("log: {level: verbose}\n", "gcsd.yaml:1: log.level: expected debug|info|warning|error, got 'verbose'"),
    ("log: {format: text}\n", "gcsd.yaml:1: log.format: expected console|json, got 'text'"),
    ("log: {tlog: ''}\n", "gcsd.yaml:1: log.tlog: expected a non-empty string or null, got ''"),
    ("- vehicle\n", "gcsd.yaml:1: expected a mapping of sections at the top level, got a list"),
    ("just words\n", "gcsd.yaml:1: expected a mapping of sections at the top level, got 'just words'"),
]


@pytest.mark.parametrize(("text", "expected"), BAD_CONFIGS, ids=[e.split(": ")[1] for _, e in BAD_CONFIGS])
def test_bad_config_is_reported_as_file_line_key_path_and_what_is_wrong(text, expected):
    assert problems(text) == [expected]


@pytest.mark.parametrize(("text", "line"), [
    ("vehicle:\n  type: copter\n sysid: 1\n", 3),
    ("vehicle: {sysid: 1\nlog: {}\n", 2),
    ("vehicle:\n\ttype: copter\n", 2),
    ("--- {}\n--- {}\n", 2),
])
def test_yaml_syntax_error_is_one_problem_with_its_line(text, line):
    [problem] = problems(text)
    assert problem.startswith(f"gcsd.yaml:{line}: invalid YAML: ")


def test_unknown_key_is_reported_with_line_and_suggestion():
    assert problems("""
        vehicle:
          type: plane
          sysid: 3
          speeedup: 2
    """) == ["gcsd.yaml:5: vehicle.speeedup: unknown key; did you mean 'speedup'?"]


def test_all_problems_are_reported_at_once_in_line_order():
    assert problems("""
        vehicle:
          sysid: 300
          colour: red
        channels:
          - name: gcs
            type: udp-server
            address: foo
          - name: gcs
            type: serial
            device: /dev/ttyS0
        log: {level: loud}
    """) == [
        "gcsd.yaml:3: vehicle.sysid: expected an integer 1..255, got 300",
        "gcsd.yaml:4: vehicle.colour: unknown key (known keys: type, sysid, compid, count, home, speedup, camera, gimbal)",
        "gcsd.yaml:8: channels[0].address: expected HOST:PORT, got 'foo'",
        "gcsd.yaml:9: channels[1].name: duplicate channel name 'gcs' (also channels[0])",
        "gcsd.yaml:12: log.level: expected debug|info|warning|error, got 'loud'",
    ]


def test_more_than_ten_channels_is_a_problem():
    channels = "".join(f"  - {{name: c{i}, type: udp-server, address: '127.0.0.1:0'}}\n" for i in range(11))
    assert problems("channels:\n" + channels) == [
        "gcsd.yaml:2: channels: expected 1 to 10 channels (SR0_ .. SR9_), got 11",
    ]


def test_signing_key_problem_never_shows_the_key():
    secret = "ab" * 31 + "zz"
    [problem] = problems(f"signing: {{key: {secret}}}")
    assert secret not in problem


def test_load_config_names_the_file_as_given(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("bad.yaml").write_text("vehicle:\n  sysid: 0\n")
    with pytest.raises(ConfigError) as caught:
        load_config("bad.yaml")
    assert caught.value.problems == ["bad.yaml:2: vehicle.sysid: expected an integer 1..255, got 0"]
    assert str(caught.value) == "bad.yaml:2: vehicle.sysid: expected an integer 1..255, got 0"


def test_missing_file_is_a_config_error(tmp_path):
    missing = tmp_path / "nope.yaml"
    with pytest.raises(ConfigError) as caught:
        load_config(missing)
    assert caught.value.problems == [f"{missing}: cannot read: No such file or directory"]


def test_parse_config_names_an_unnamed_text_config():
    with pytest.raises(ConfigError) as caught:
        parse_config("vehicle: {sysid: 0}")
    assert caught.value.problems == ["<config>:1: vehicle.sysid: expected an integer 1..255, got 0"]
