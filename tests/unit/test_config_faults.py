"""Configuration faults through the real command line: each one is exit 2 and one
``FILE:LINE: key.path: what is wrong`` line on stderr (never a traceback, never a daemon that
starts half-working). `gcsd run` faults that need the filesystem are found before any channel
opens (preflight.prepare); `gcsd check-config` finds the same ones without creating anything."""

from __future__ import annotations

import os
import random
import subprocess
import sys
import time
from pathlib import Path

import pytest
from logging_fixture import restore_logging  # noqa: F401  (an autouse fixture)

from gcsd.config import ConfigError, parse_config
from gcsd.daemon.cli import main

REPO = Path(__file__).resolve().parents[2]
LOOPBACK = '[{name: gcs, type: udp-server, address: "127.0.0.1:0"}]'




@pytest.fixture
def here(tmp_path, monkeypatch):
    """Work in tmp_path, as a user who runs gcsd from a directory of their own."""
    monkeypatch.chdir(tmp_path)
    return tmp_path


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def cli(argv: list[str], capsys) -> tuple[int, list[str]]:
    code = main(argv)
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return code, err.splitlines()


def run_and_check(config: Path, capsys) -> tuple[tuple[int, list[str]], tuple[int, list[str]]]:
    return cli(["check-config", str(config)], capsys), cli(["run", "-c", str(config)], capsys)


# --- state_dir --------------------------------------------------------------------------------


def test_state_dir_through_a_file_is_refused_by_check_config_and_run(here, capsys):
    (here / "afile").write_text("not a directory")
    config = write(here / "g.yaml", f"channels: {LOOPBACK}\nstate_dir: ./afile/state\n")
    check, run = run_and_check(config, capsys)
    assert check == (2, [f"{config}:2: state_dir: cannot create afile/state: afile is not a directory"])
    assert run == (2, [f"{config}:2: state_dir: cannot use afile/state as the state directory: Not a directory"])


def test_state_dir_that_is_a_file_is_refused(here, capsys):
    (here / "afile").write_text("not a directory")
    config = write(here / "g.yaml", f"state_dir: afile\nchannels: {LOOPBACK}\n")
    check, run = run_and_check(config, capsys)
    assert check == (2, [f"{config}:1: state_dir: cannot create afile: afile is not a directory"])
    assert run[0] == 2 and run[1] == [f"{config}:1: state_dir: cannot use afile as the state directory: File exists"]


def test_state_dir_where_nothing_can_be_created_is_refused_at_run(here, capsys):
    config = write(here / "g.yaml", f"state_dir: /sys/gcsd-test-state\nchannels: {LOOPBACK}\n")
    code, lines = cli(["run", "-c", str(config)], capsys)
    assert code == 2
    assert len(lines) == 1 and lines[0].startswith(
        f"{config}:1: state_dir: cannot use /sys/gcsd-test-state as the state directory: ")


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into a mode 0500 directory")
def test_state_dir_in_a_read_only_directory_is_refused(here, capsys):
    (here / "ro").mkdir(mode=0o500)
    config = write(here / "g.yaml", f"state_dir: ro/state\nchannels: {LOOPBACK}\n")
    check, run = run_and_check(config, capsys)
    assert check == (2, [f"{config}:1: state_dir: cannot create or write ro/state: ro is not writable"])
    assert run == (2, [f"{config}:1: state_dir: cannot use ro/state as the state directory: Permission denied"])


def test_built_in_default_with_an_unusable_state_dir_names_the_key(here, capsys):
    (here / "gcsd-state").write_text("a file where the default state directory goes")
    code, lines = cli(["run"], capsys)
    assert code == 2
    assert lines == [("(built-in default configuration): state_dir: cannot use gcsd-state as the state directory: "
                      "File exists")]


# --- NUL bytes in paths -------------------------------------------------------------------------


@pytest.mark.parametrize(("yaml_text", "where"), [
    ('state_dir: "st\\0ate"\n', "1: state_dir"),
    ('params_file: "a\\0.parm"\n', "1: params_file"),
    ('ftp: {root: "ft\\0p"}\n', "1: ftp.root"),
    ('log:\n  tlog: "x\\0.tlog"\n', "2: log.tlog"),
    ('channels:\n  - {name: fc, type: serial, device: "/dev/tty\\0S0"}\n', "2: channels[0].device"),
    ('serial_control:\n  - {port: telem1, device: "/dev/tty\\0S1"}\n', "2: serial_control[0].device"),
])
def test_a_nul_byte_in_any_path_is_refused(here, capsys, yaml_text, where):
    config = write(here / "g.yaml", yaml_text)
    check, run = run_and_check(config, capsys)
    expected = (2, [f"{config}:{where}: a path cannot contain a NUL byte"])
    assert check == expected and run == expected


def test_a_nul_byte_in_a_host_is_refused(here, capsys):
    config = write(here / "g.yaml", 'channels:\n  - {name: g, type: udp-server, address: "127.0.0.1\\0:14550"}\n')
    assert cli(["check-config", str(config)], capsys) == (
        2, [f"{config}:2: channels[0].address: expected HOST:PORT, got '127.0.0.1\\x00:14550'"])


# --- broken and hostile YAML --------------------------------------------------------------------


def test_yaml_nested_3000_deep_is_one_line_not_a_recursion_error(here, capsys):
    config = write(here / "g.yaml", "vehicle:\n  home: " + "[" * 3000 + "]" * 3000 + "\n")
    check, run = run_and_check(config, capsys)
    expected = (2, [f"{config}:2: invalid YAML: nested more than 32 levels deep"])
    assert check == expected and run == expected


def test_deep_yaml_in_a_real_process_prints_one_line_and_exits_2(here):
    config = write(here / "g.yaml", "a: " + "{b: " * 3000 + "1" + "}" * 3000 + "\n")
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    result = subprocess.run([sys.executable, "-m", "gcsd", "-c", str(config)], check=False, capture_output=True,
                            text=True, env=env, timeout=60)
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr.splitlines() == [f"{config}:1: invalid YAML: nested more than 32 levels deep"]


@pytest.mark.parametrize(("text", "expected"), [
    ("vehicle: {sysid: 1\n", "2: invalid YAML: expected ',' or '}', but got '<stream end>'"),
    ("vehicle:\n\tsysid: 1\n", "2: invalid YAML: found character '\\t' that cannot start any token"),
    ("a: 1\n---\nb: 2\n", "2: invalid YAML: expected a single document in the stream, but found another document"),
    ('state_dir: "unclosed\n', "2: invalid YAML: found unexpected end of stream"),
    ("channels: *nowhere\n", "1: invalid YAML: found undefined alias 'nowhere'"),
])
def test_yaml_syntax_errors_are_one_line_with_the_line_number(here, capsys, text, expected):
    config = write(here / "g.yaml", text)
    assert cli(["check-config", str(config)], capsys) == (2, [f"{config}:{expected}"])


def test_invalid_utf8_names_its_line(here, capsys):
    config = here / "g.yaml"
    config.write_bytes(b"vehicle:\n  type: copter\nstate_dir: caf\xe9\n")
    assert cli(["check-config", str(config)], capsys) == (2, [f"{config}:3: invalid UTF-8 (byte 0xe9)"])


@pytest.mark.parametrize("source", ["huge", "/dev/zero"])
def test_a_huge_file_or_an_endless_device_is_refused_without_reading_it_all(here, capsys, source):
    path = here / "huge.yaml" if source == "huge" else Path(source)
    if source == "huge":
        path.write_text("# padding\n" * 200_000)  # 2 MB of comments
    start = time.monotonic()
    assert cli(["check-config", str(path)], capsys) == (2, [f"{path}:1: the file is larger than 1048576 bytes"])
    assert time.monotonic() - start < 2.0


def test_an_alias_bomb_is_answered_at_once(here, capsys):
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, 10)]  # 9**10 leaves
    config = write(here / "g.yaml", "\n".join(lines) + "\nchannels: *a9\nserial_control: *a9\n")
    start = time.monotonic()
    code, problems = cli(["check-config", str(config)], capsys)
    assert code == 2 and time.monotonic() - start < 2.0
    assert problems[0] == f"{config}:1: a0: unknown key (known keys: vehicle, state_dir, params_file, gcs, " \
                          "mission, ftp, signing, channels, log, serial_control, routing, flight_logs, can, http, metrics)"
    assert any(p.endswith(": channels[0]: expected a mapping, got a list") for p in problems)
    assert any(p.endswith(": serial_control[8]: expected a mapping, got a list") for p in problems)


def test_a_recursive_alias_is_refused_not_followed(here, capsys):
    config = write(here / "g.yaml", "vehicle: &v {home: *v}\n")
    assert cli(["check-config", str(config)], capsys) == (
        2, [f"{config}:1: vehicle.home.home: unknown key (known keys: lat, lon, alt)"])


def test_seeded_random_damage_to_the_shipped_file_never_raises_anything_but_config_error():
    base = (REPO / "config" / "gcsd.yaml").read_text()
    pieces = list(":-[]{}&*!|>'\"%@`#,?\n \t\\0x.~") + ["\0", "\x85", "\ufeff", "!!python/object:os.system",
                                                        "&a ", "*a", "<<: *a", "!!binary", "0x", "1e999"]
    rng = random.Random(11)
    for _ in range(150):
        text = list(base)
        for _ in range(rng.randint(1, 6)):
            pos = rng.randrange(len(text))
            if rng.random() < 0.5:
                text[pos] = rng.choice(pieces)
            else:
                text.insert(pos, rng.choice(pieces))
        try:
            parse_config("".join(text), "fuzz.yaml")
        except ConfigError as exc:
            assert exc.problems and all(p.startswith("fuzz.yaml:") for p in exc.problems)


# --- two channels on one address or device ------------------------------------------------------


@pytest.mark.parametrize(("first", "second", "what"), [
    ("{name: a, type: udp-server, address: '127.0.0.1:14599'}", "{name: b, type: udp-server, address: '127.0.0.1:14599'}",
     "channels[1].address: UDP port 14599 on 127.0.0.1 is already bound by channels[0] (a)"),
    ("{name: a, type: udp-server, address: '0.0.0.0:14599'}", "{name: b, type: udp-server, address: '127.0.0.1:14599'}",
     "channels[1].address: UDP port 14599 on 127.0.0.1 is already bound by channels[0] (a)"),
    ("{name: a, type: tcp-server, address: '127.0.0.1:5760'}", "{name: b, type: tcp-server, address: '[::]:5760'}",
     "channels[1].address: TCP port 5760 on :: is already bound by channels[0] (a)"),
    ("{name: a, type: udp-client, address: '10.0.0.9:14550'}", "{name: b, type: udp-client, address: '10.0.0.9:14550'}",
     "channels[1].address: 10.0.0.9:14550 is already the address of channels[0] (a)"),
    ("{name: a, type: serial, device: /dev/ttyUSB0}", "{name: b, type: serial, device: /dev//ttyUSB0}",
     "channels[1].device: serial device /dev//ttyUSB0 is already used by channels[0] (a)"),
])
def test_two_channels_on_one_port_or_device_are_refused_by_check_config_and_run(here, capsys, first, second, what):
    config = write(here / "g.yaml", f"channels:\n  - {first}\n  - {second}\n")
    check, run = run_and_check(config, capsys)
    assert check == (2, [f"{config}:3: {what}"]) and run == check


def test_a_serial_control_port_on_a_channels_device_or_another_ports_device_is_refused(here, capsys):
    config = write(here / "g.yaml", "channels:\n  - {name: fc, type: serial, device: /dev/ttyAMA0}\n"
                                    "serial_control:\n  - {port: telem1, device: /dev/ttyAMA0}\n"
                                    "  - {port: gps1, device: /dev/ttyUSB1}\n  - {port: gps2, device: /dev/ttyUSB1}\n")
    assert cli(["check-config", str(config)], capsys) == (2, [
        f"{config}:4: serial_control[0].device: serial device /dev/ttyAMA0 is already used by channels[0] (fc)",
        f"{config}:6: serial_control[2].device: serial device /dev/ttyUSB1 is already used by serial_control port gps1",
    ])


@pytest.mark.parametrize("pair", [
    ("{name: a, type: udp-server, address: '127.0.0.1:14599'}", "{name: b, type: tcp-server, address: '127.0.0.1:14599'}"),
    ("{name: a, type: udp-server, address: '127.0.0.1:0'}", "{name: b, type: udp-server, address: '127.0.0.1:0'}"),
    ("{name: a, type: udp-server, address: '127.0.0.1:14599'}", "{name: b, type: udp-server, address: '127.0.0.2:14599'}"),
    ("{name: a, type: udp-server, address: '127.0.0.1:14550'}", "{name: b, type: udp-client, address: '127.0.0.1:14550'}"),
])
def test_channels_that_do_not_collide_are_accepted(pair):
    parse_config(f"channels:\n  - {pair[0]}\n  - {pair[1]}\n")


# --- max_peers ------------------------------------------------------------------------------------


def test_max_peers_defaults_to_8_and_takes_1_to_64_on_servers():
    config = parse_config("channels:\n  - {name: a, type: udp-server, address: '127.0.0.1:0'}\n"
                          "  - {name: b, type: tcp-server, address: '127.0.0.1:0', max_peers: 64}\n")
    assert [c.max_peers for c in config.channels] == [8, 64]


@pytest.mark.parametrize(("channel", "what"), [
    ("{name: a, type: udp-server, address: '127.0.0.1:0', max_peers: 0}",
     "channels[0].max_peers: expected an integer 1..64, got 0"),
    ("{name: a, type: tcp-server, address: '127.0.0.1:0', max_peers: 65}",
     "channels[0].max_peers: expected an integer 1..64, got 65"),
    ("{name: a, type: udp-client, address: '127.0.0.1:14550', max_peers: 2}",
     "channels[0].max_peers: only used by udp-server and tcp-server channels"),
])
def test_bad_max_peers_is_refused(here, capsys, channel, what):
    config = write(here / "g.yaml", f"channels:\n  - {channel}\n")
    assert cli(["check-config", str(config)], capsys) == (2, [f"{config}:2: {what}"])


# --- params_file ------------------------------------------------------------------------------------


def test_params_file_value_too_large_for_real32_is_refused_with_the_params_file_line(here, capsys):
    parm = write(here / "start.parm", "# my settings\nRC4_TRIM 1480\nCOMPASS_OFS_X 1e39\n")
    config = write(here / "g.yaml", f"params_file: start.parm\nstate_dir: st\nchannels: {LOOPBACK}\n")
    check, run = run_and_check(config, capsys)
    expected = (2, [f"{parm.name}:3: COMPASS_OFS_X: 1e+39 is out of range for a REAL32 (a 32-bit float)"])
    assert check == expected and run == expected
    assert not (here / "st" / "mav.parm").exists(), "nothing was started, nothing saved"


@pytest.mark.parametrize(("line", "what"), [
    ("COMPASS_OFS_X nan", "COMPASS_OFS_X: nan is not a finite number"),
    ("COMPASS_OFS_X -inf", "COMPASS_OFS_X: -inf is not a finite number"),
    ("NO_SUCH_PARAM 3", "NO_SUCH_PARAM: no such parameter"),
    ("ANGLE_MAX 100000", "ANGLE_MAX: 100000 is out of range for its type (-32768..32767)"),
    ("this is not a parameter line", "expected NAME VALUE: 'this is not a parameter line'"),
    ("RC1_TRIM 1.2.3", "RC1_TRIM: '1.2.3' is not a number"),
])
def test_every_bad_params_file_line_is_refused_with_its_line(here, capsys, line, what):
    write(here / "p.parm", f"RC4_TRIM 1480\n{line}\n")
    config = write(here / "g.yaml", f"params_file: p.parm\nstate_dir: st\nchannels: {LOOPBACK}\n")
    assert cli(["check-config", str(config)], capsys) == (2, [f"p.parm:2: {what}"])


def test_a_value_outside_the_parameters_documented_range_is_accepted_as_a_param_set_is(here, capsys):
    write(here / "p.parm", "RC1_TRIM 5000\nANGLE_MAX 9000\n")
    config = write(here / "g.yaml", f"params_file: p.parm\nstate_dir: st\nchannels: {LOOPBACK}\n")
    assert cli(["check-config", str(config)], capsys)[0] == 0
    write(here / "p.parm", "RC1_TRIM 5000\nANGLE_MAX 100000\n")  # the control: its type's range still holds
    assert cli(["check-config", str(config)], capsys)[0] == 2


def test_a_missing_params_file_names_the_config_line(here, capsys):
    config = write(here / "g.yaml", f"state_dir: st\nparams_file: missing.parm\nchannels: {LOOPBACK}\n")
    check, run = run_and_check(config, capsys)
    expected = (2, [f"{config}:2: params_file: cannot read missing.parm: No such file or directory"])
    assert check == expected and run == expected


def test_sysid_thismav_in_the_params_file_of_a_swarm_is_refused(here, capsys):
    write(here / "p.parm", "RC4_TRIM 1480\nSYSID_THISMAV 7\n")
    config = write(here / "g.yaml", f"vehicle: {{count: 3}}\nparams_file: p.parm\nstate_dir: st\nchannels: {LOOPBACK}\n")
    check, run = run_and_check(config, capsys)
    expected = (2, [("p.parm:2: SYSID_THISMAV: would give all 3 vehicles of the swarm one sysid; "
                     "their sysids come from vehicle.sysid")])
    assert check == expected and run == expected


# --- ftp.root ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("root", [".", "./", "./."])
def test_ftp_root_equal_to_the_state_directory_is_refused(here, capsys, root):
    config = write(here / "g.yaml", f"ftp:\n  root: '{root}'\n")
    assert cli(["check-config", str(config)], capsys) == (
        2, [(f"{config}:2: ftp.root: must be a directory under state_dir, not state_dir itself "
             "(FTP clients could read the signing key and the saved parameters)")])


def test_ftp_root_that_is_a_link_back_to_the_state_directory_is_refused_at_run(here, capsys):
    (here / "st").mkdir()
    (here / "st" / "ftp").symlink_to("..")
    config = write(here / "g.yaml", f"state_dir: st\nchannels: {LOOPBACK}\n")
    code, lines = cli(["run", "-c", str(config)], capsys)
    assert code == 2
    assert lines == [(f"{config}:1: ftp.root: st/ftp resolves to {here}, "
                      f"which holds the state directory {here / 'st'}: "
                      "FTP clients could read the signing key and the saved parameters")]


def test_ftp_root_that_is_a_file_is_refused_at_run(here, capsys):
    (here / "st").mkdir()
    (here / "st" / "ftp").write_text("a file")
    config = write(here / "g.yaml", f"state_dir: st\nchannels: {LOOPBACK}\n")
    code, lines = cli(["run", "-c", str(config)], capsys)
    assert (code, lines) == (2, [f"{config}:1: ftp.root: cannot use st/ftp as the FTP root: File exists"])
