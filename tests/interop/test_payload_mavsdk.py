"""MAVSDK's camera and gimbal plugins (the `mavsdk` package, 4.x) drive the real daemon (`gcsd run`)
with `vehicle.camera` and `vehicle.gimbal` on.

Camera: the plugin lists the camera it finds by its HEARTBEAT (compid 100) and CAMERA_INFORMATION,
takes a photo (IMAGE_START_CAPTURE to the camera) and reports the capture event from
CAMERA_IMAGE_CAPTURED (a new index, capture_result 1) with the position of that instant.
Gimbal: the plugin finds the gimbal from GIMBAL_MANAGER_INFORMATION, takes primary control
(DO_GIMBAL_MANAGER_CONFIGURE, seen back in GIMBAL_MANAGER_STATUS), sets angles and reports the
attitude (GIMBAL_DEVICE_ATTITUDE_STATUS) as it slews there.
"""

from __future__ import annotations

import asyncio

import pytest

pytest.importorskip("mavsdk.asyncio", reason="mavsdk is a test extra: pip install -e .[test]")

from mavsdk.asyncio.plugins.camera import CameraAsync
from mavsdk.asyncio.plugins.gimbal import ControlMode, GimbalAsync, GimbalMode, SendMode

from .test_mavsdk import _first, _ground_station

WAIT_S = 10.0
CAMERA_COMPID = 100


async def _poll(get, accept, what: str, timeout_s: float = WAIT_S):
    """The plugin's latest value, asked until `accept` takes it (a subscription reports changes only)."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    value = None
    while loop.time() < deadline:
        value = await get()
        if accept(value):
            return value
        await asyncio.sleep(0.05)
    pytest.fail(f"MAVSDK reported no {what} within {timeout_s} s; last: {value}", pytrace=False)


@pytest.mark.interop
async def test_mavsdk_camera_lists_the_camera_and_takes_a_photo(gcsd_daemon, home_position):
    daemon = gcsd_daemon({"vehicle": {"camera": True}})
    async with _ground_station(daemon.port("gcs")) as (_, _connect_s, system):
        assert system is not None, daemon.describe()
        camera = CameraAsync(system)
        try:
            cameras = await _first(camera.subscribe_camera_list(), lambda c: len(c.cameras) > 0, WAIT_S, "camera")
            info = cameras.cameras[0]
            assert info.component_id == CAMERA_COMPID
            assert (info.vendor_name, info.model_name) == ("gcsd", "SimCam")
            assert (info.horizontal_resolution_px, info.vertical_resolution_px) == (640, 480)
            captures = camera.subscribe_capture_info()
            first = asyncio.ensure_future(_first(captures, lambda c: c.is_success, WAIT_S, "capture"))
            await asyncio.sleep(0.2)  # the subscription is in place before the photo
            await camera.take_photo(CAMERA_COMPID)
            capture = await first
            assert capture.index >= 0 and capture.file_url.endswith(".JPG")
            assert capture.position.latitude_deg == pytest.approx(home_position.lat_deg, abs=1e-5)
            assert capture.position.longitude_deg == pytest.approx(home_position.lon_deg, abs=1e-5)
            assert capture.position.absolute_altitude_m == pytest.approx(home_position.alt_m, abs=2.0)
        finally:
            camera.destroy()


@pytest.mark.interop
async def test_mavsdk_gimbal_takes_control_sets_angles_and_the_attitude_follows(gcsd_daemon):
    daemon = gcsd_daemon({"vehicle": {"gimbal": True}})
    async with _ground_station(daemon.port("gcs")) as (_, _connect_s, system):
        assert system is not None, daemon.describe()
        gimbal = GimbalAsync(system)
        try:
            gimbals = await _first(gimbal.subscribe_gimbal_list(), lambda g: len(g.gimbals) > 0, WAIT_S, "gimbal")
            item = gimbals.gimbals[0]
            assert item.gimbal_manager_component_id == 1 and item.gimbal_device_id == 1
            gimbal_id = item.gimbal_id
            await gimbal.take_control(gimbal_id, ControlMode.PRIMARY)
            status = await _poll(lambda: gimbal.get_control_status(gimbal_id),
                                 lambda s: s.control_mode == ControlMode.PRIMARY, "primary control")
            assert (status.sysid_primary_control, status.compid_primary_control) == (245, 190)  # MAVSDK's own ids
            # before: the default mode's attitude (RC targeting, centred inputs: the middle of -90..20)
            before = await _first(gimbal.subscribe_attitude(),
                                  lambda a: abs(a.euler_angle_forward.pitch_deg + 35) < 0.5, WAIT_S,
                                  "the default attitude")
            assert abs(before.euler_angle_forward.yaw_deg) < 0.5
            await gimbal.set_angles(gimbal_id, 0.0, -50.0, 30.0, GimbalMode.YAW_FOLLOW, SendMode.ONCE)
            there = await _first(gimbal.subscribe_attitude(),
                                 lambda a: abs(a.euler_angle_forward.pitch_deg + 50) < 0.5
                                 and abs(a.euler_angle_forward.yaw_deg - 30) < 0.5, WAIT_S, "the set attitude")
            assert there.gimbal_id == gimbal_id
            assert there.euler_angle_north.yaw_deg == pytest.approx(30.0, abs=0.5)  # the vehicle faces north
            await gimbal.release_control(gimbal_id)
            await _poll(lambda: gimbal.get_control_status(gimbal_id), lambda s: s.control_mode == ControlMode.NONE,
                        "control released")
        finally:
            gimbal.destroy()
