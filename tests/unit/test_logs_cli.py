"""`gcsd logs [-c FILE] [--json]`: the logs a configuration keeps, per vehicle, without a daemon."""

from __future__ import annotations

import json

from logging_fixture import restore_logging  # noqa: F401  (an autouse fixture)

from gcsd.daemon.cli import main
from gcsd.payloads.logs.store import LogStore


def write_config(tmp_path, extra: str = "") -> str:
    path = tmp_path / "g.yaml"
    path.write_text(f"state_dir: {tmp_path / 'state'}\n{extra}")
    return str(path)


def test_logs_lists_id_size_start_and_path(tmp_path, capsys):
    store = LogStore(tmp_path / "state" / "logs", 100, 0)
    f = store.create(1_767_225_600.0)  # 2026-01-01 00:00:00 UTC
    f.append(b"x" * 1234)
    f.finish()
    capsys.readouterr()
    assert main(["logs", "-c", write_config(tmp_path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].split() == ["1", "1", "1234", "2026-01-01", "00:00:00", str(tmp_path / "state/logs/00000001.BIN")]
    assert main(["logs", "-c", write_config(tmp_path), "--json"]) == 0
    [entry] = json.loads(capsys.readouterr().out)
    assert entry == {"sysid": 1, "id": 1, "name": "00000001.BIN", "size": 1234, "time_utc": 1_767_225_600,
                     "path": str(tmp_path / "state/logs/00000001.BIN")}


def test_a_swarm_has_one_directory_per_vehicle(tmp_path, capsys):
    LogStore(tmp_path / "state" / "vehicle-2" / "bin", 100, 0).create(1.0).finish()
    config = write_config(tmp_path, "vehicle: {count: 2, sysid: 10}\nflight_logs: {dir: bin}\n")
    capsys.readouterr()
    assert main(["logs", "-c", config, "--json"]) == 0
    assert [(e["sysid"], e["id"]) for e in json.loads(capsys.readouterr().out)] == [(11, 1)]


def test_no_logs_says_where_it_looked_and_a_bad_config_exits_2(tmp_path, capsys):
    assert main(["logs", "-c", write_config(tmp_path)]) == 0
    assert capsys.readouterr().out.startswith(f"no flight logs in {tmp_path / 'state' / 'logs'}")
    bad = tmp_path / "bad.yaml"
    bad.write_text("flight_logs: {max_files: 0}\n")
    assert main(["logs", "-c", str(bad)]) == 2
    assert "flight_logs.max_files" in capsys.readouterr().err
