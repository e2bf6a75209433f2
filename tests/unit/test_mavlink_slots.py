"""The HTTP API's own channel (type local) is no MAVLink channel for SRn_ purposes
(config_schema.mavlink_slot): the parameter set is ArduPilot's with or without the API, the API's
link runs the fixed default rates whatever SRn_ says, it takes none of the ten MAVLink slots, and
a channel added at run time after it gets the next SRn_ group (the one it gets again when it is
restored before the API's channel at the next start)."""

from __future__ import annotations

import yaml
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.clock import Clock
from gcsd.config import parse_config
from gcsd.config.schema import DEFAULT_STREAM_RATES_HZ, LOCAL_TYPE, MAX_CHANNELS, ChannelConfig, mavlink_slot
from gcsd.daemon.daemon import Daemon

RAW_IMU = M.MAVLINK_MSG_ID_RAW_IMU  # stream raw_sens
DEFAULT_RAW_SENS_MS = 1000 // DEFAULT_STREAM_RATES_HZ["raw_sens"]


def _udp(name: str) -> dict:
    return {"name": name, "type": "udp-server", "address": "127.0.0.1:0"}


def _gcs(tmp_path, channels: list[dict], http: dict | None = None) -> Daemon:
    data = {"state_dir": str(tmp_path), "channels": channels}
    if http is not None:
        data["http"] = http
    config = parse_config(yaml.safe_dump(data), "t.yaml")
    return Daemon(config, Clock(monotonic=lambda: 100.0, wall=lambda: 1.8e9))


def _param_set(gcs: Daemon, name: str, value: float) -> None:
    channel = gcs.channels[0]
    peer = channel.peers.get("station") or channel.add_peer("station", lambda data: True, 100.0)
    mav = M.MAVLink(None, srcSystem=255, srcComponent=190)
    msg = M.MAVLink_param_set_message(1, 1, name.encode(), value, M.MAV_PARAM_TYPE_INT16)
    channel.receive(peer, bytes(msg.pack(mav)), 100.0)


def test_the_slot_is_the_place_among_the_mavlink_channels():
    types = ["udp-server", "serial", LOCAL_TYPE, "tcp-client"]
    assert [mavlink_slot(types, i) for i in range(len(types))] == [0, 1, None, 2]


def test_the_parameter_set_is_the_same_with_and_without_the_api(tmp_path):
    on = _gcs(tmp_path / "on", [_udp("gcs")])
    off = _gcs(tmp_path / "off", [_udp("gcs")], http={"address": None})
    assert [ch.name for ch in on.channels] == ["gcs", "http"]
    assert [ch.name for ch in off.channels] == ["gcs"]
    listed = [(e.name, e.value) for e in on.nodes[0].params.entries() if e.name != "STAT_RUNTIME"]
    assert listed == [(e.name, e.value) for e in off.nodes[0].params.entries() if e.name != "STAT_RUNTIME"]
    assert on.nodes[0].params.get("SR1_RAW_SENS") == 0  # ArduPilot's default: no channel 1


def test_the_api_link_keeps_the_default_rates_whatever_srn_says(tmp_path):
    gcs = _gcs(tmp_path, [_udp("gcs")])
    node, (gcs_ch, http_ch) = gcs.nodes[0], gcs.channels
    assert node.link(http_ch).interval_ms(RAW_IMU) == DEFAULT_RAW_SENS_MS
    _param_set(gcs, "SR1_RAW_SENS", 10)
    _param_set(gcs, "SR0_RAW_SENS", 4)
    assert node.params.get("SR1_RAW_SENS") == 10
    assert node.link(http_ch).interval_ms(RAW_IMU) == DEFAULT_RAW_SENS_MS
    assert node.link(gcs_ch).interval_ms(RAW_IMU) == 250  # SR0_ acts on channel 0 (the control)


def test_a_channel_added_after_the_api_takes_the_next_srn_group(tmp_path):
    gcs = _gcs(tmp_path, [_udp("gcs")])
    node = gcs.nodes[0]
    _param_set(gcs, "SR1_RAW_SENS", 10)
    index = gcs.free_slot()
    assert index == 2  # after gcs and http
    lte = gcs.attach(index, ChannelConfig(name="lte", type="udp-server", address=("127.0.0.1", 0)))
    assert node.link(lte).interval_ms(RAW_IMU) == 100  # SR1_RAW_SENS 10 Hz
    _param_set(gcs, "SR1_RAW_SENS", 4)
    assert node.link(lte).interval_ms(RAW_IMU) == 250  # and follows it at once
    assert node.link(gcs.channels[1]).interval_ms(RAW_IMU) == DEFAULT_RAW_SENS_MS  # the API's: unchanged


def test_the_api_takes_none_of_the_ten_mavlink_slots(tmp_path):
    nine = _gcs(tmp_path / "nine", [_udp(f"c{i}") for i in range(MAX_CHANNELS - 1)])
    index = nine.free_slot()
    assert index == MAX_CHANNELS  # the tenth MAVLink channel, after the API's
    last = nine.attach(index, ChannelConfig(name="last", type="udp-server", address=("127.0.0.1", 0)))
    assert mavlink_slot([ch.config.type for ch in nine.channels], last.index) == MAX_CHANNELS - 1
    assert nine.free_slot() is None  # ten MAVLink channels: full
    ten = _gcs(tmp_path / "ten", [_udp(f"c{i}") for i in range(MAX_CHANNELS)])
    assert ten.free_slot() is None and len(ten.channels) == MAX_CHANNELS + 1
