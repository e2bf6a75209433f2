"""The command line: subcommands, exit codes and what is printed."""

import json
import logging
import os
import subprocess
import sys
import types
from pathlib import Path

import pytest
import structlog

import gcsd
from gcsd.cli import main
from gcsd.config import default_config, load_config

REPO = Path(__file__).resolve().parents[2]
DEFAULT_YAML = REPO / "config" / "gcsd.yaml"
BAD_YAML = "vehicle:\n  sysid: 0\nlog:\n  level: loud\n"


@pytest.fixture
def bad_config(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(BAD_YAML)
    return path


@pytest.fixture
def daemon(monkeypatch):
    """A stand-in for gcsd.app: records the configs it was run with, returns `exit_code`."""
    app = types.ModuleType("gcsd.app")
    app.runs = []
    app.exit_code = 0
    app.failure = None

    async def run_daemon(config):
        app.runs.append(config)
        structlog.get_logger("gcsd.app").info("daemon_started", sysid=config.vehicle.sysid)
        structlog.get_logger("gcsd.app").debug("detail_logged")
        if app.failure:
            raise app.failure
        return app.exit_code

    app.run_daemon = run_daemon
    monkeypatch.setitem(sys.modules, "gcsd.app", app)
    yield app


@pytest.fixture(autouse=True)
def restore_logging():
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    yield
    structlog.reset_defaults()
    root.handlers[:] = handlers
    root.setLevel(level)


# --- check-config -----------------------------------------------------------------------------------


def test_check_config_of_the_shipped_file_prints_ok_and_exits_0(capsys):
    assert main(["check-config", str(DEFAULT_YAML)]) == 0
    out, err = capsys.readouterr()
    assert out == f"{DEFAULT_YAML}: ok\n"
    assert err == ""


def test_check_config_prints_every_problem_on_stderr_and_exits_2(bad_config, capsys):
    assert main(["check-config", str(bad_config)]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.splitlines() == [
        f"{bad_config}:2: vehicle.sysid: expected an integer 1..255, got 0",
        f"{bad_config}:4: log.level: expected debug|info|warning|error, got 'loud'",
    ]


def test_check_config_of_a_missing_file_exits_2(tmp_path, capsys):
    assert main(["check-config", str(tmp_path / "missing.yaml")]) == 2
    assert "cannot read" in capsys.readouterr().err


def test_python_m_gcsd_check_config_of_a_bad_file_exits_2(bad_config):
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    result = subprocess.run([sys.executable, "-m", "gcsd", "check-config", str(bad_config)],
                            capture_output=True, text=True, env=env, timeout=60)
    assert result.returncode == 2
    first_problem = f"{bad_config}:2: vehicle.sysid: expected an integer 1..255, got 0"
    assert result.stderr.splitlines()[0] == first_problem


def test_python_m_gcsd_check_config_of_a_good_file_exits_0():
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    result = subprocess.run([sys.executable, "-m", "gcsd", "check-config", str(DEFAULT_YAML)],
                            capture_output=True, text=True, env=env, timeout=60)
    assert (result.returncode, result.stdout) == (0, f"{DEFAULT_YAML}: ok\n")


# --- arguments and --version ------------------------------------------------------------------------


def test_version_prints_the_package_version_and_exits_0(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"gcsd {gcsd.__version__}\n"
    assert gcsd.__version__ == "0.1.0"


@pytest.mark.parametrize("argv", [["check-config"], ["fly"], ["run", "--frobnicate"], ["run", "-c"]])
def test_bad_arguments_exit_2(argv, capsys):
    assert main(argv) == 2
    assert "usage: gcsd" in capsys.readouterr().err


def test_help_exits_0(capsys):
    assert main(["--help"]) == 0
    assert "check-config" in capsys.readouterr().out


# --- run ----------------------------------------------------------------------------------------------


def test_run_with_a_bad_config_exits_2_without_starting_the_daemon(bad_config, daemon, capsys):
    assert main(["run", "-c", str(bad_config)]) == 2
    assert daemon.runs == []
    out, err = capsys.readouterr()
    assert out == ""
    assert err.splitlines()[0] == f"{bad_config}:2: vehicle.sysid: expected an integer 1..255, got 0"


def test_no_command_runs_the_daemon_with_the_built_in_default(daemon):
    assert main([]) == 0
    assert daemon.runs == [default_config()]


def test_run_loads_the_file_and_returns_the_daemon_exit_code(daemon):
    daemon.exit_code = 1
    assert main(["run", "-c", str(DEFAULT_YAML)]) == 1
    assert daemon.runs == [load_config(DEFAULT_YAML)]


def test_run_logs_json_lines_on_stdout_at_the_configured_level(tmp_path, daemon, capsys):
    path = tmp_path / "json.yaml"
    path.write_text("vehicle: {sysid: 7}\nlog: {level: info, format: json}\n")
    assert main(["run", "--config", str(path)]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    events = [(line["event"], line["level"], line["sysid"]) for line in lines]
    assert events == [("daemon_started", "info", 7)]
    assert lines[0]["timestamp"].endswith("Z")


def test_run_exits_1_when_the_daemon_fails(daemon, capsys):
    daemon.failure = RuntimeError("boom")
    assert main(["run"]) == 1
    assert "daemon_failed" in capsys.readouterr().out
