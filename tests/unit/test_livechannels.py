"""Channels at run time, the pure parts: a runtime channel's spec checked as the configuration is,
and what a reload changes."""

from gcsd.config import parse_config
from gcsd.daemon.livechannels import channel_from_spec, plan_reload, restart_sections


def channels(text: str):
    return parse_config(text).channels


RUNNING = channels("channels:\n  - {name: gcs, type: udp-server, address: '0.0.0.0:14550'}\n"
                   "  - {name: fc, type: serial, device: /dev/ttyACM0}\n")


def test_a_good_spec_becomes_a_channel():
    channel, error = channel_from_spec({"name": "lte", "type": "udp-client", "address": "fc-modem.local:14550"},
                                       list(RUNNING))
    assert error is None and channel.address == ("fc-modem.local", 14550)


def test_a_spec_gets_the_configuration_checks_as_one_line_without_file_and_line():
    assert channel_from_spec({"name": "x", "type": "udp-server", "address": "nowhere"}, []) == (
        None, "address: expected HOST:PORT, got 'nowhere'")
    assert channel_from_spec({"name": "x", "type": "serial"}, []) == (None, "device: required for type serial")
    assert channel_from_spec({"name": "x", "colour": 1}, [])[1].startswith("expected the keys")


def test_a_spec_that_clashes_with_a_running_channel_is_refused():
    assert channel_from_spec({"name": "gcs", "type": "udp-client", "address": "1.2.3.4:5"}, list(RUNNING)) == (
        None, "name: a channel named 'gcs' is already running")
    _, error = channel_from_spec({"name": "two", "type": "udp-server", "address": "127.0.0.1:14550"}, list(RUNNING))
    assert error == "address: UDP port 14550 on 127.0.0.1 is already bound by channel gcs"
    _, error = channel_from_spec({"name": "two", "type": "serial", "device": "/dev/ttyACM0"}, list(RUNNING))
    assert error == "device: serial device /dev/ttyACM0 is already used by channel fc"


def test_a_reload_touches_only_what_changed():
    new = channels("channels:\n  - {name: gcs, type: udp-server, address: '0.0.0.0:14550'}\n"
                   "  - {name: fc, type: serial, device: /dev/ttyACM0, baud: 57600}\n"
                   "  - {name: lte, type: udp-client, address: '10.0.0.2:14550'}\n")
    plan = plan_reload(RUNNING, new)
    assert plan.close == () and [c.name for c in plan.reopen] == ["fc"] and [c.name for c in plan.open] == ["lte"]
    assert plan_reload(new, RUNNING).close == ("lte",)
    assert plan_reload(RUNNING, RUNNING) == plan_reload((), ())


def test_sections_other_than_channels_need_a_restart():
    old = parse_config("vehicle: {sysid: 1}\n")
    assert restart_sections(old, parse_config("vehicle: {sysid: 2}\nrouting: {dedup_ms: 5}\n")) == ["vehicle", "routing"]
    assert restart_sections(old, parse_config("channels: [{name: a, type: udp-server, address: '1.2.3.4:5'}]\n")) == []
