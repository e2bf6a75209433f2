"""The `http` section (config_http.py): defaults, null, the loopback rule, the token file."""

from textwrap import dedent

import pytest

from gcsd.config import ConfigError, default_config, parse_config, preflight
from gcsd.daemon.cli import main


def parse(text: str):
    return parse_config(dedent(text), "gcsd.yaml")


def problems(text: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse(text)
    return caught.value.problems


def test_default_is_loopback_8088_without_token():
    assert default_config().http.address == ("127.0.0.1", 8088)
    assert parse("vehicle: {type: copter}\n").http.address == ("127.0.0.1", 8088)
    assert parse("http: {}\n").http.token_file is None


def test_null_turns_it_off_and_an_address_is_read():
    assert parse("http: {address: null}\n").http.address is None
    assert parse("http: {address: 'localhost:9000'}\n").http.address == ("localhost", 9000)


def test_non_loopback_needs_a_token_file():
    assert problems("""\
        vehicle: {type: copter}
        http:
          address: 0.0.0.0:8088
        """) == [("gcsd.yaml:3: http.address: 0.0.0.0 is not a loopback address: set http.token_file too "
                  "(the API can arm the vehicle)")]
    assert parse("http: {address: '0.0.0.0:8088', token_file: /etc/gcsd/token}\n").http.token_file == "/etc/gcsd/token"


@pytest.mark.parametrize("text,where", [
    ("http: {address: nope}\n", "http.address: expected HOST:PORT"),
    ("http: {adress: '127.0.0.1:1'}\n", "http.adress"),
    ("http: 5\n", "http: expected a mapping"),
    ("http: {token_file: ''}\n", "http.token_file"),
])
def test_bad_values_say_where(text, where):
    found = problems(text)
    assert len(found) == 1 and found[0].startswith("gcsd.yaml:1: ") and where in found[0]


def test_token_file_is_checked_before_the_start(tmp_path, capsys):
    empty = tmp_path / "token"
    empty.write_text("\n")
    config_file = tmp_path / "gcsd.yaml"
    config_file.write_text(f"state_dir: {tmp_path / 'state'}\nhttp:\n  token_file: {empty}\n")
    assert main(["check-config", str(config_file)]) == 2
    err = capsys.readouterr().err
    assert f"{config_file}:3: http.token_file: cannot read a token from {empty}: the first line is empty" in err
    empty.write_text("abc\n")
    assert main(["check-config", str(config_file)]) == 0
    config = parse_config(config_file.read_text(), str(config_file))
    assert preflight.check(config) == []
    missing = parse_config(f"http: {{token_file: {tmp_path / 'none'}}}\n", "x.yaml")
    assert "No such file" in preflight.check(missing)[0]
