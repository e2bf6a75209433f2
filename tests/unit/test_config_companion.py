"""The companion-routing configuration keys: filter, rate_limits, group, baud lists, request_streams,
sign_forwarded and routing.dedup_ms."""

from textwrap import dedent

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.config import ConfigError, parse_config
from gcsd.config.companion import ChannelFilter, FilterRules, RoutingConfig


def config(channel: str, top: str = ""):
    text = "channels:\n  - name: radio\n" + "".join(f"    {line}\n" for line in dedent(channel).splitlines())
    return parse_config(text + dedent(top), "c.yaml")


def problems(channel: str, top: str = "") -> list[str]:
    with pytest.raises(ConfigError) as caught:
        config(channel, top)
    return caught.value.problems


UDP = "type: udp-server\naddress: 127.0.0.1:14550\n"


def test_no_companion_key_means_no_filter_no_caps_no_group():
    c = config(UDP)
    ch = c.channels[0]
    assert ch.filter == ChannelFilter() and dict(ch.rate_limits) == {} and ch.group is None
    assert ch.request_streams == 0 and c.routing == RoutingConfig(dedup_ms=0)


def test_filters_take_dialect_names_and_numbers_in_both_directions():
    ch = config(UDP + dedent("""\
        filter:
          in: {block_msgids: [PARAM_VALUE, 253], allow_src_sys: [1, 255]}
          out: {allow_msgids: [heartbeat, ATTITUDE], block_src_comp: [191]}
    """)).channels[0]
    assert ch.filter.inbound == FilterRules(block_msgids=frozenset({M.MAVLINK_MSG_ID_PARAM_VALUE, 253}),
                                            allow_src_sys=frozenset({1, 255}))
    assert ch.filter.outbound == FilterRules(allow_msgids=frozenset({0, M.MAVLINK_MSG_ID_ATTITUDE}),
                                             block_src_comp=frozenset({191}))


def test_an_unknown_message_name_is_a_problem_on_its_line_with_a_suggestion():
    assert problems(UDP + "filter:\n  in: {block_msgids: [ATTITUDE, ATTITUDEE]}\n") == [
        ("c.yaml:6: channels[0].filter.in.block_msgids[1]: unknown message 'ATTITUDEE' in the ardupilotmega "
         "dialect; did you mean 'ATTITUDE'?")]


@pytest.mark.parametrize(("text", "expected"), [
    ("filter: {sideways: {}}\n", "c.yaml:5: channels[0].filter.sideways: unknown key (known keys: in, out)"),
    ("filter: {in: {block_msgid: [1]}}\n",
     "c.yaml:5: channels[0].filter.in.block_msgid: unknown key; did you mean 'block_msgids'?"),
    ("filter: {out: {allow_src_sys: [256]}}\n",
     "c.yaml:5: channels[0].filter.out.allow_src_sys[0]: expected an integer 0..255, got 256"),
    ("filter: {in: {block_msgids: [16777216]}}\n",
     "c.yaml:5: channels[0].filter.in.block_msgids[0]: a message id must be 0..16777215, got 16777216"),
    ("rate_limits: {ATTITUDE: 0}\n", "c.yaml:5: channels[0].rate_limits.ATTITUDE: expected a number > 0 and <= 1000.0, got 0"),
    ("rate_limits: {NOPE: 5}\n", "c.yaml:5: channels[0].rate_limits.NOPE: unknown message 'NOPE' in the ardupilotmega dialect"),
    ("rate_limits: [ATTITUDE]\n", "c.yaml:5: channels[0].rate_limits: expected a mapping of message name or id to Hz, got a list"),
    ("request_streams: 51\n", "c.yaml:5: channels[0].request_streams: expected an integer 0..50, got 51"),
    ("options: [sign_forwarded]\n", "c.yaml:5: channels[0].options: sign_forwarded is allowed only on serial"),
])
def test_bad_companion_keys_are_file_line_key_path_problems(text, expected):
    channel = "type: udp-server\naddress: 0.0.0.0:14550\n" + text
    got = problems(channel)
    assert len(got) == 1 and got[0].startswith(expected), got


def test_rate_limits_by_name_or_number():
    ch = config(UDP + "rate_limits: {ATTITUDE: 10, 33: 2.5}\n").channels[0]
    assert dict(ch.rate_limits) == {M.MAVLINK_MSG_ID_ATTITUDE: 10.0, 33: 2.5}


def test_a_message_named_twice_in_rate_limits_is_a_problem():
    assert problems(UDP + "rate_limits: {ATTITUDE: 10, 30: 5}\n") == [
        "c.yaml:5: channels[0].rate_limits.30: duplicate message"]


@pytest.mark.parametrize("channel", [
    "type: serial\ndevice: /dev/ttyACM0\noptions: [sign_forwarded]\n",
    "type: udp-server\naddress: 127.0.0.1:14600\noptions: [sign_forwarded]\n",
    "type: tcp-client\naddress: localhost:5760\noptions: [sign_forwarded]\n",
    "type: udp-client\naddress: '[::1]:14550'\noptions: [sign_forwarded]\n",
])
def test_sign_forwarded_is_accepted_on_serial_and_loopback_channels(channel):
    assert "sign_forwarded" in config(channel).channels[0].options


def test_a_baud_list_is_tried_in_order_and_the_first_sets_the_default_bandwidth():
    ch = config("type: serial\ndevice: /dev/ttyACM0\nbaud: [921600, 57600]\n").channels[0]
    assert ch.bauds == (921600, 57600) and ch.baud == 921600 and ch.bandwidth == 92160
    assert config("type: serial\ndevice: /dev/ttyACM0\nbaud: 57600\n").channels[0].bauds == (57600,)


def test_group_request_streams_and_dedup():
    c = config(UDP + "group: fc\nrequest_streams: 4\n", "routing: {dedup_ms: 200}\n")
    assert c.channels[0].group == "fc" and c.channels[0].request_streams == 4
    assert c.routing.dedup_ms == 200
    assert problems(UDP, "routing: {dedup_ms: -1}\n") == [
        "c.yaml:5: routing.dedup_ms: expected an integer 0..10000, got -1"]


def test_host_names_are_accepted_as_addresses():
    c = config("type: udp-client\naddress: fc-modem.local:14550\n")
    assert c.channels[0].address == ("fc-modem.local", 14550)


def test_check_config_reports_companion_keys_as_file_line_key_path(tmp_path, capsys):
    from gcsd.daemon.cli import main

    conf = tmp_path / "companion.yaml"
    conf.write_text(dedent(f"""\
        state_dir: {tmp_path / 'state'}
        channels:
          - name: radio
            type: serial
            device: /dev/ttyACM0
            baud: [921600, 57600]
            group: fc
            filter: {{out: {{allow_msgids: [HEARTBEAT, ATTITUDEX]}}}}
          - name: lan
            type: udp-server
            address: 0.0.0.0:14550
            options: [sign_forwarded]
            rate_limits: {{ATTITUDE: -1}}
        routing: {{dedup_ms: 200}}
    """))
    assert main(["check-config", str(conf)]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == (f"{conf}:8: channels[0].filter.out.allow_msgids[1]: unknown message 'ATTITUDEX' in the "
                        "ardupilotmega dialect; did you mean 'ATTITUDE'?")
    assert lines[1].startswith(f"{conf}:12: channels[1].options: sign_forwarded is allowed only on serial")
    assert lines[2] == f"{conf}:13: channels[1].rate_limits.ATTITUDE: expected a number > 0 and <= 1000.0, got -1"
    assert len(lines) == 3
