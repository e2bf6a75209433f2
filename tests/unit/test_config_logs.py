"""The flight_logs section: defaults, values, and each problem as FILE:LINE: key.path: what."""

from __future__ import annotations

from textwrap import dedent

import pytest
from logging_fixture import restore_logging  # noqa: F401  (an autouse fixture)

from gcsd.config import ConfigError, default_config, parse_config
from gcsd.config.logs import FlightLogsConfig
from gcsd.daemon.cli import main


def problems(text: str) -> list[str]:
    with pytest.raises(ConfigError) as err:
        parse_config(dedent(text), "g.yaml")
    return err.value.problems


def test_defaults_are_the_documented_ones():
    assert default_config().flight_logs == FlightLogsConfig("logs", False, (), True, 100, 100)
    assert parse_config("flight_logs: null\n").flight_logs == FlightLogsConfig()


def test_values_are_read():
    c = parse_config(dedent("""\
        channels:
          - {name: fc, type: udp-server, address: "127.0.0.1:0"}
        flight_logs: {dir: flight/bin, capture: true, channels: [fc], simulated: false, max_files: 5,
                      min_free_mb: 0}
    """)).flight_logs
    assert c == FlightLogsConfig("flight/bin", True, ("fc",), False, 5, 0)


@pytest.mark.parametrize(("text", "expected"), [
    ("flight_logs: {dir: /var/log}\n", "g.yaml:1: flight_logs.dir: expected a path relative to state_dir"),
    ("flight_logs: {dir: ../x}\n", "g.yaml:1: flight_logs.dir: expected a path relative to state_dir"),
    ("flight_logs: {dir: .}\n", "g.yaml:1: flight_logs.dir: must be a directory under state_dir"),
    ("flight_logs:\n  capture: yes please\n", "g.yaml:2: flight_logs.capture: expected true or false"),
    ("flight_logs: {channels: [radio]}\n", "g.yaml:1: flight_logs.channels[0]: no channel is named 'radio'"),
    ("flight_logs: {channels: [gcs, gcs]}\n", "g.yaml:1: flight_logs.channels[1]: channel 'gcs' is listed twice"),
    ("flight_logs: {max_files: 0}\n", "g.yaml:1: flight_logs.max_files: expected an integer 1..10000"),
    ("flight_logs: {min_free_mb: -1}\n", "g.yaml:1: flight_logs.min_free_mb: expected an integer 0..1000000"),
    ("flight_logs: {max_file: 3}\n", "g.yaml:1: flight_logs.max_file: unknown key; did you mean 'max_files'?"),
])
def test_problems_name_the_line_and_key(text, expected):
    assert any(p.startswith(expected) for p in problems(text)), problems(text)


def test_a_log_directory_that_is_a_file_is_refused_by_check_config_and_run(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "st").mkdir()
    (tmp_path / "st" / "logs").write_text("a file")
    config = tmp_path / "g.yaml"
    config.write_text('state_dir: st\nchannels: [{name: gcs, type: udp-server, address: "127.0.0.1:0"}]\n'
                      "flight_logs:\n  dir: logs\n")
    assert main(["check-config", str(config)]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"{config}:4: flight_logs.dir: cannot create st/logs: st/logs is not a directory"]
    assert main(["run", "-c", str(config)]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"{config}:4: flight_logs.dir: cannot use st/logs for flight logs: File exists"]
