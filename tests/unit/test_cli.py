"""The command line: subcommands, exit codes and what is printed."""

import json
import os
import subprocess
import sys
import types
from pathlib import Path

import pytest
import structlog
from logging_fixture import restore_logging  # noqa: F401  (an autouse fixture)

import gcsd
from gcsd.config import default_config, load_config
from gcsd.daemon.cli import main
from gcsd.loop import loop_name
from gcsd.wire import speedups

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
    """A stand-in for gcsd.daemon.app: records the configs it was run with, returns `exit_code`."""
    app = types.ModuleType("gcsd.daemon.app")
    app.runs = []
    app.exit_code = 0
    app.failure = None

    async def run_daemon(config):
        app.runs.append(config)
        structlog.get_logger("gcsd.daemon.app").info("daemon_started", sysid=config.vehicle.sysid)
        structlog.get_logger("gcsd.daemon.app").debug("detail_logged")
        if app.failure:
            raise app.failure
        return app.exit_code

    app.run_daemon = run_daemon
    monkeypatch.setitem(sys.modules, "gcsd.daemon.app", app)
    yield app




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
                            check=False, capture_output=True, text=True, env=env, timeout=60)
    assert result.returncode == 2
    first_problem = f"{bad_config}:2: vehicle.sysid: expected an integer 1..255, got 0"
    assert result.stderr.splitlines()[0] == first_problem


def test_python_m_gcsd_check_config_of_a_good_file_exits_0():
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    result = subprocess.run([sys.executable, "-m", "gcsd", "check-config", str(DEFAULT_YAML)],
                            check=False, capture_output=True, text=True, env=env, timeout=60)
    assert (result.returncode, result.stdout) == (0, f"{DEFAULT_YAML}: ok\n")


# --- arguments and --version ------------------------------------------------------------------------


def test_version_prints_the_package_version_and_exits_0(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"gcsd {gcsd.__version__} ({loop_name()}, {speedups.DESCRIPTION})\n"
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


# --- gcsd -c FILE --------------------------------------------------------------------------------------


def test_dash_c_before_any_command_runs_the_file_as_the_sitl_headers_write_it(daemon):
    assert main(["-c", str(DEFAULT_YAML)]) == 0
    assert main(["--config", str(DEFAULT_YAML), "run"]) == 0
    assert daemon.runs == [load_config(DEFAULT_YAML)] * 2


def test_dash_c_with_a_bad_file_exits_2_without_starting(bad_config, daemon, capsys):
    assert main(["-c", str(bad_config)]) == 2
    assert daemon.runs == []
    assert capsys.readouterr().err.splitlines()[0] == f"{bad_config}:2: vehicle.sysid: expected an integer 1..255, got 0"


def test_dash_c_before_check_config_is_refused_with_a_hint(capsys):
    assert main(["-c", str(DEFAULT_YAML), "check-config", str(DEFAULT_YAML)]) == 2
    assert capsys.readouterr().err == "gcsd: check-config takes the file as its argument: gcsd check-config FILE\n"


def test_python_m_gcsd_dash_c_of_a_bad_file_exits_2(bad_config):
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    result = subprocess.run([sys.executable, "-m", "gcsd", "-c", str(bad_config)],
                            check=False, capture_output=True, text=True, env=env, timeout=60)
    assert result.returncode == 2
    assert result.stderr.splitlines()[0] == f"{bad_config}:2: vehicle.sysid: expected an integer 1..255, got 0"


# --- status tables -------------------------------------------------------------------------------------

STATUS = {
    "version": "0.1.0", "uptime_s": 3725.2,
    "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:14550", "peers": 2, "rate_in": 12.4,
                  "rate_out": 85.0, "packets_in": 1200, "packets_out": 9000, "bytes_in": 40000, "bytes_out": 512000,
                  "parse_errors": 1, "crc_errors": 2, "unknown_ids": 3, "seq_gaps": 4, "drops": 5,
                  "signature_rejects": 6, "peers_forgotten": 7, "peers_replaced": 8,
                  "signature_reject_reasons": {"bad_signature": 6}}],
    "routes": [{"sysid": 255, "compid": 190, "channel": "gcs", "mavtype": 6, "age_s": 0.42},
               {"sysid": 42, "compid": 1, "channel": "gcs", "mavtype": None, "age_s": 3.0}],
    "vehicles": [{"sysid": 1, "compid": 1, "type": "copter", "mode": "STABILIZE", "armed": False}],
    "errors": {"producer:SYS_STATUS": 3, "handler:PARAM_SET": 1},
}


def test_status_tables_have_titles_units_and_mav_type_names():
    from gcsd.api.control import format_status

    text = format_status(STATUS, {"pid": 4321, "config": "/etc/gcsd/gcsd.yaml"})
    lines = text.splitlines()
    assert lines[0] == "gcsd 0.1.0, up 1 h 2 min (pid 4321, config /etc/gcsd/gcsd.yaml)"
    for title in ("Channels", "Channel errors and drops (counts)", "Routes learned", "Vehicles",
                  "Errors (exceptions caught, by component)"):
        assert title in lines
    for header in ("in (pkt/s)", "out (pkt/s)", "in (B)", "out (B)", "last heard (s ago)"):
        assert header in text
    routes = lines[lines.index("Routes learned") + 3:lines.index("Routes learned") + 5]
    assert routes[0].split() == ["255", "190", "GCS", "gcs", "0.4"]
    assert routes[1].split() == ["42", "1", "-", "gcs", "3.0"]  # no heartbeat yet: no type
    errors = lines[lines.index("Errors (exceptions caught, by component)") + 3:]
    assert [e.split() for e in errors[:2]] == [["handler:PARAM_SET", "1"], ["producer:SYS_STATUS", "3"]]
    assert "Signing rejects by reason: gcs: bad_signature 6" in text


def test_status_shows_none_for_empty_tables():
    from gcsd.api.control import format_status

    text = format_status({**STATUS, "routes": [], "errors": {}})
    assert "Routes learned: none" in text.splitlines()
    assert "Errors (exceptions caught, by component): none" in text.splitlines()
    assert text.splitlines()[0] == "gcsd 0.1.0, up 1 h 2 min"


@pytest.mark.parametrize(("mav_type", "name"), [(2, "QUADROTOR"), (1, "FIXED_WING"), (6, "GCS"), (None, "-"),
                                                (999, "999")])
def test_mav_type_names(mav_type, name):
    from gcsd.api.control import mav_type_name

    assert mav_type_name(mav_type) == name


@pytest.mark.parametrize("answer", [b"garbage\n", b'["a list"]\n', b'{"version": "9"}\n'])
def test_status_of_a_socket_that_is_not_gcsd_exits_1_with_one_line(tmp_path, monkeypatch, capsys, answer):
    import socket
    import threading

    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path / "run"))
    config = tmp_path / "g.yaml"
    config.write_text(f"state_dir: {tmp_path / 'st'}\n")
    (tmp_path / "st").mkdir()
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(tmp_path / "st" / "gcsd.sock"))
    server.listen(1)

    def answer_once() -> None:
        conn, _ = server.accept()
        with conn:
            conn.sendall(answer)

    thread = threading.Thread(target=answer_once)
    thread.start()
    try:
        assert main(["status", "-c", str(config)]) == 1
    finally:
        thread.join(5)
        server.close()
    err = capsys.readouterr().err
    assert err.startswith(f"gcsd status: no daemon answers on {tmp_path / 'st' / 'gcsd.sock'} (")
    assert len(err.splitlines()) == 1 and "Traceback" not in err


def test_status_table_shows_what_was_dropped_on_purpose():
    from gcsd.api.control import format_status

    channel = {**STATUS["channels"][0], "spoofed_dropped": 31, "retained_dropped": 32, "loop_dropped": 33,
               "unauthenticated_closed": 34, "accept_failures": 35}
    text = format_status({**STATUS, "channels": [channel]})
    lines = text.splitlines()
    at = lines.index("Channel errors and drops (counts)")
    headers, row = lines[at + 1], lines[at + 3].split()
    for header in ("spoofed", "retained", "loop", "unauth closed", "accept failed"):
        assert header in headers
    assert row[-5:] == ["31", "32", "33", "34", "35"]
