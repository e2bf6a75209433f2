"""How compose.py fits the payload onto a vehicle (payload.py): nothing by default; with the gimbal, the
MNT1_ group, its producers (EXTRA3 carrying GIMBAL_DEVICE_ATTITUDE_STATUS) and the ROI hook, except on
an antenna tracker, which points itself at the ROI; with the camera, compid 100 as a local component."""

from __future__ import annotations

import yaml
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.boundary import ErrorCounts
from gcsd.clock import Clock
from gcsd.config import parse_config
from gcsd.daemon.compose import build_vehicle
from gcsd.links.channel import Channel
from gcsd.wire.signing import SigningManager


def build(tmp_path, vehicle: str = "copter", **payload):
    data = {"vehicle": {"type": vehicle, **payload}, "state_dir": str(tmp_path / vehicle),
            "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]}
    config = parse_config(yaml.safe_dump(data), "t.yaml")
    clock = Clock(monotonic=lambda: 100.0, wall=lambda: 1.8e9)
    channel = Channel(0, config.channels[0], clock.now)
    return build_vehicle(0, config, clock, [channel], lambda ch: None, ErrorCounts(),
                         SigningManager(None, False, None, clock.wall()))


def test_by_default_nothing_is_fitted(tmp_path):
    node = build(tmp_path)
    assert "MNT1_DEFLT_MODE" not in node.params and node.params.get("MNT1_TYPE") == 0
    assert M.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS not in node.producers
    assert node.autopilot.mount_roi is None and node.local_compids == []


def test_a_gimbal_brings_its_parameters_producers_stream_and_roi(tmp_path):
    node = build(tmp_path, gimbal=True)
    assert node.params.get("MNT1_TYPE") == 7 and node.params.get("MNT1_PITCH_MIN") == -90
    assert M.MAVLINK_MSG_ID_GIMBAL_MANAGER_STATUS in node.producers
    assert node.links[0].interval_ms(M.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS) == 500  # EXTRA3, 2 Hz
    assert node.autopilot.mount_roi is not None


def test_an_antenna_tracker_keeps_the_roi_for_itself(tmp_path):
    node = build(tmp_path, "tracker", gimbal=True)
    assert node.autopilot.mount_roi is None
    assert M.MAVLINK_MSG_ID_GIMBAL_MANAGER_STATUS in node.producers


def test_a_camera_is_a_local_component(tmp_path):
    node = build(tmp_path, camera=True)
    assert node.local_compids == [100]
    assert M.MAV_CMD_DO_DIGICAM_CONTROL in node.autopilot.payload_items
