"""The gimbal (`vehicle.gimbal: true`) against the real daemon over UDP with pymavlink: what
QGroundControl's GimbalController sends, step by step (src/Gimbal/GimbalController.cc), and what
ArduPilot 4.6 with a mount answers; the gimbal keeps pointing at an ROI while the vehicle flies."""

from __future__ import annotations

import math

import pytest

from gcsd.payloads.gimbal.geometry import euler

from .helpers import M, is_ack, wait_for

QGC = (255, 190)
NAN = math.nan
DEVICE_STATUS = M.MAVLINK_MSG_ID_GIMBAL_DEVICE_ATTITUDE_STATUS
MANAGER_STATUS = M.MAVLINK_MSG_ID_GIMBAL_MANAGER_STATUS
MANAGER_INFO = M.MAVLINK_MSG_ID_GIMBAL_MANAGER_INFORMATION


@pytest.fixture
def gimbal(daemon, client):
    d = daemon({"vehicle": {"gimbal": True},
                "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]})
    gcs = client(f"udpout:127.0.0.1:{d.port('gcs')}", *QGC)
    gcs.heartbeat()
    assert wait_for(gcs, lambda r: r.type == "HEARTBEAT" and r.src == (1, 1))
    return gcs


def command(gcs, cmd: int, *params: float, timeout: float = 3.0) -> int | None:
    mark = gcs.mark()
    gcs.command_long(cmd, *params)
    r = wait_for(gcs, is_ack(cmd), timeout, since=mark)
    return None if r is None else r.msg.result


def attitude_deg(gcs, since: int) -> tuple[float, float, float] | None:
    r = wait_for(gcs, lambda r: r.type == "GIMBAL_DEVICE_ATTITUDE_STATUS", 3.0, since=since)
    return None if r is None else tuple(math.degrees(a) for a in euler(list(r.msg.q)))


def settled(gcs, pitch: float, yaw: float, timeout: float = 6.0, tol: float = 0.5):
    """Wait until the reported attitude is at (pitch, body yaw); returns it (or the last seen)."""
    last = None

    def at(r):
        nonlocal last
        if r.type != "GIMBAL_DEVICE_ATTITUDE_STATUS":
            return False
        last = tuple(math.degrees(a) for a in euler(list(r.msg.q)))
        return abs(last[1] - pitch) < tol and abs(((last[2] - yaw) + 180) % 360 - 180) < tol

    return wait_for(gcs, at, timeout, since=gcs.mark()), last


def test_qgc_discovery_sequence_finds_the_gimbal(gimbal):
    gcs = gimbal
    # 1. on the autopilot's HEARTBEAT: REQUEST_MESSAGE(GIMBAL_MANAGER_INFORMATION) to that compid
    mark = gcs.mark()
    assert command(gcs, M.MAV_CMD_REQUEST_MESSAGE, MANAGER_INFO) == M.MAV_RESULT_ACCEPTED
    info = wait_for(gcs, lambda r: r.type == "GIMBAL_MANAGER_INFORMATION", since=mark)
    assert info is not None and info.src == (1, 1)
    assert info.msg.gimbal_device_id == 1  # QGC rejects device id 0
    assert info.msg.cap_flags & M.GIMBAL_MANAGER_CAP_FLAGS_HAS_PITCH_AXIS
    assert info.msg.cap_flags & M.GIMBAL_MANAGER_CAP_FLAGS_HAS_YAW_AXIS
    assert (info.msg.pitch_min, info.msg.pitch_max) == pytest.approx((math.radians(-90), math.radians(20)))
    # 2. SET_MESSAGE_INTERVAL(GIMBAL_MANAGER_STATUS, 0 = default): ArduPilot has no default for it;
    #    QGC's last retries ask 0.2 Hz (5 000 000 us)
    assert command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, MANAGER_STATUS, 0) == M.MAV_RESULT_ACCEPTED
    mark = gcs.mark()
    assert command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, MANAGER_STATUS, 5_000_000) == M.MAV_RESULT_ACCEPTED
    status = wait_for(gcs, lambda r: r.type == "GIMBAL_MANAGER_STATUS", 6.0, since=mark)
    assert status is not None and status.msg.gimbal_device_id == 1 and status.src == (1, 1)
    # 3. SET_MESSAGE_INTERVAL(GIMBAL_DEVICE_ATTITUDE_STATUS, 0): its default is EXTRA3's rate
    mark = gcs.mark()
    assert command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, DEVICE_STATUS, 0) == M.MAV_RESULT_ACCEPTED
    att = wait_for(gcs, lambda r: r.type == "GIMBAL_DEVICE_ATTITUDE_STATUS", since=mark)
    assert att is not None and att.msg.gimbal_device_id == 1
    assert att.msg.flags & M.GIMBAL_DEVICE_FLAGS_YAW_IN_VEHICLE_FRAME
    # the default mode (RC targeting, centred inputs) points at the middle of the pitch range
    assert settled(gcs, -35.0, 0.0)[0] is not None


def test_qgc_acquire_point_and_release(gimbal):
    gcs = gimbal
    assert command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, DEVICE_STATUS, 100_000) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, MANAGER_STATUS, 200_000) == M.MAV_RESULT_ACCEPTED
    # acquireGimbalControl: (own sysid, own compid, -1, -1, NaN, NaN, device)
    assert command(gcs, M.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE, *QGC, -1, -1, NAN, NAN, 1) == M.MAV_RESULT_ACCEPTED
    assert wait_for(gcs, lambda r: r.type == "GIMBAL_MANAGER_STATUS"
                    and (r.msg.primary_control_sysid, r.msg.primary_control_compid) == QGC)
    # sendPitchBodyYaw: (pitch, yaw, NaN, NaN, ROLL_LOCK | PITCH_LOCK | YAW_IN_VEHICLE_FRAME, 0, device)
    flags = M.GIMBAL_MANAGER_FLAGS_ROLL_LOCK | M.GIMBAL_MANAGER_FLAGS_PITCH_LOCK | \
        M.GIMBAL_MANAGER_FLAGS_YAW_IN_VEHICLE_FRAME
    mark = gcs.mark()
    assert command(gcs, M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, -60, 45, NAN, NAN, flags, 0, 1) == M.MAV_RESULT_ACCEPTED
    first = attitude_deg(gcs, mark)
    assert first is not None and first[1] > -59  # a finite slew: not there at once
    hit, last = settled(gcs, -60.0, 45.0)
    assert hit is not None, f"the gimbal never reached -60/45: last {last}"
    # sendRate: NaN angles, rates (deg/s): rate control, yaw still in the vehicle frame
    assert command(gcs, M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, NAN, NAN, 10, 0, flags, 0, 1) == M.MAV_RESULT_ACCEPTED
    hit, last = settled(gcs, -40.0, 45.0, tol=3.0)
    assert hit is not None, f"the rate never moved the pitch: last {last}"
    # releaseGimbalControl: -3, -3
    assert command(gcs, M.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE, -3, -3, -1, -1, NAN, NAN, 1) == M.MAV_RESULT_ACCEPTED
    assert wait_for(gcs, lambda r: r.type == "GIMBAL_MANAGER_STATUS" and r.msg.primary_control_sysid == 0)


def test_commands_answer_as_ardupilot_with_a_mount(gimbal):
    gcs = gimbal
    assert command(gcs, M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, 0, 0, NAN, NAN, 0, 0, 2) == M.MAV_RESULT_FAILED
    assert command(gcs, M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, 10, NAN, NAN, 5, 0, 0, 1) == M.MAV_RESULT_FAILED
    assert command(gcs, M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, NAN, NAN, NAN, NAN, 0, 0, 0) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE, -4, 0, 0, 0, 0, 0, 1) == M.MAV_RESULT_FAILED
    assert command(gcs, M.MAV_CMD_DO_MOUNT_CONTROL, -20, 0, 30, 0, 0, 0,
                   M.MAV_MOUNT_MODE_MAVLINK_TARGETING) == M.MAV_RESULT_ACCEPTED
    mark = gcs.mark()
    assert command(gcs, M.MAV_CMD_DO_MOUNT_CONTROL, -2000, 0, 0, 0, 0, 0,
                   M.MAV_MOUNT_MODE_MAVLINK_TARGETING) == M.MAV_RESULT_FAILED
    assert wait_for(gcs, lambda r: r.type == "STATUSTEXT" and r.msg.text == "Mount: invalid angle targets", since=mark)
    assert command(gcs, M.MAV_CMD_DO_MOUNT_CONFIGURE, M.MAV_MOUNT_MODE_NEUTRAL) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_DO_SET_ROI_SYSID, 7) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, math.inf, 0, NAN, NAN, 0, 0, 1) == M.MAV_RESULT_DENIED


def test_mnt1_parameters_are_there_and_act(gimbal):
    gcs = gimbal
    mark = gcs.mark()
    gcs.send(M.MAVLink_param_request_read_message(1, 1, b"MNT1_PITCH_MIN", -1))
    r = wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == "MNT1_PITCH_MIN", since=mark)
    assert r is not None and r.msg.param_value == -90
    gcs.send(M.MAVLink_param_set_message(1, 1, b"MNT1_PITCH_MIN", -45, M.MAV_PARAM_TYPE_REAL32))
    assert wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and r.msg.param_id == "MNT1_PITCH_MIN"
                    and r.msg.param_value == -45, since=mark)
    assert command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, DEVICE_STATUS, 100_000) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, -80, 0, NAN, NAN, 0, 0, 1) == M.MAV_RESULT_ACCEPTED
    hit, last = settled(gcs, -45.0, 0.0)
    assert hit is not None, f"MNT1_PITCH_MIN did not limit the pitch: {last}"


def test_roi_location_keeps_the_gimbal_on_target_while_the_vehicle_flies(gimbal):
    gcs = gimbal
    from gcsd.vehicle.sim.geo import offset
    assert command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, DEVICE_STATUS, 100_000) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 100_000) == \
        M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_DO_SET_MODE, 1, 4) == M.MAV_RESULT_ACCEPTED  # GUIDED
    assert command(gcs, M.MAV_CMD_COMPONENT_ARM_DISARM, 1) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 20) == M.MAV_RESULT_ACCEPTED
    target = offset(-35.363262, 149.165237, 60.0, 0.0)  # 60 m north of home, on the ground
    mark = gcs.mark()
    gcs.send(M.MAVLink_command_int_message(1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT, M.MAV_CMD_DO_SET_ROI_LOCATION,
                                           0, 0, NAN, NAN, NAN, NAN, round(target[0] * 1e7), round(target[1] * 1e7), 0))
    ack = wait_for(gcs, lambda r: is_ack(M.MAV_CMD_DO_SET_ROI_LOCATION)(r), since=mark)
    assert ack is not None and ack.msg.result == M.MAV_RESULT_ACCEPTED

    def pointing_error_deg(r_att, r_pos) -> float:
        """Angle between where the gimbal looks and where the target is, from the vehicle."""
        from gcsd.vehicle.sim import geo
        _roll, pitch, yaw_bf = euler(list(r_att.msg.q))
        lat, lon, alt = r_pos.msg.lat / 1e7, r_pos.msg.lon / 1e7, r_pos.msg.relative_alt / 1000
        heading = math.radians(r_pos.msg.hdg / 100)
        north, east = geo.ne_m(lat, lon, *target)
        want_pitch = math.atan2(-alt, math.hypot(north, east))
        want_yaw = math.atan2(east, north)
        d_yaw = math.degrees((yaw_bf + heading - want_yaw + math.pi) % (2 * math.pi) - math.pi)
        return max(abs(math.degrees(pitch - want_pitch)), abs(d_yaw) * math.cos(want_pitch))

    climbed = wait_for(gcs, lambda r: r.type == "GLOBAL_POSITION_INT" and r.msg.relative_alt > 15_000, 30.0,
                       since=gcs.mark())
    assert climbed is not None, "the vehicle never climbed"
    east = offset(-35.363262, 149.165237, 0.0, 60.0)
    gcs.send(M.MAVLink_set_position_target_global_int_message(
        0, 1, 1, M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0b110111111000, round(east[0] * 1e7), round(east[1] * 1e7),
        20, 0, 0, 0, 0, 0, 0, 0, 0))
    errors, pos = [], climbed
    for _ in range(60):  # about 6 s of flight east, the target staying north-west of the vehicle
        pos = wait_for(gcs, lambda r: r.type == "GLOBAL_POSITION_INT", since=gcs.mark())
        att = wait_for(gcs, lambda r: r.type == "GIMBAL_DEVICE_ATTITUDE_STATUS", since=gcs.mark())
        assert pos is not None and att is not None
        errors.append(pointing_error_deg(att, pos))
    from gcsd.vehicle.sim import geo
    travelled = geo.distance_m(climbed.msg.lat / 1e7, climbed.msg.lon / 1e7, pos.msg.lat / 1e7, pos.msg.lon / 1e7)
    assert travelled > 20, f"the vehicle did not fly ({travelled:.1f} m)"
    # 5.9 deg measured: a 60 deg/s slew lags the vehicle turning towards its new course
    assert max(errors) < 10.0, f"the gimbal lost the target: {max(errors):.1f} deg"


def test_attitude_status_is_in_the_extra3_stream_without_asking(gimbal):
    """ArduPilot streams GIMBAL_DEVICE_ATTITUDE_STATUS in EXTRA3 (2 Hz by default): MAVSDK lists a
    gimbal only once its attitude has come, and asks for no interval."""
    gcs = gimbal
    mark = gcs.mark()
    from .helpers import pump
    pump([gcs], 2.2)
    seen = gcs.since(mark)
    attitudes = [r for r in seen if r.type == "GIMBAL_DEVICE_ATTITUDE_STATUS" and r.src == (1, 1)]
    winds = [r for r in seen if r.type == "WIND" and r.src == (1, 1)]  # another EXTRA3 message: the control
    assert len(winds) >= 3 and len(attitudes) >= 3, (len(winds), len(attitudes))


def test_roi_sysid_points_at_the_other_systems_reported_position(gimbal, client):
    """DO_SET_ROI_SYSID 7: the gimbal points at wherever system 7's GLOBAL_POSITION_INT says it is (read
    from any link, as ArduPilot's mount), and follows it when it moves."""
    gcs = gimbal
    from gcsd.vehicle.sim.geo import offset
    assert command(gcs, M.MAV_CMD_SET_MESSAGE_INTERVAL, DEVICE_STATUS, 100_000) == M.MAV_RESULT_ACCEPTED
    assert command(gcs, M.MAV_CMD_DO_SET_ROI_SYSID, 7) == M.MAV_RESULT_ACCEPTED
    host, port = gcs.conn.destination_addr
    other = client(f"udpout:{host}:{port}", 7, 1)  # another vehicle on the same link
    other.heartbeat(M.MAV_TYPE_QUADROTOR)

    def report(north_m: float, east_m: float, alt_m: float) -> None:
        lat, lon = offset(-35.363262, 149.165237, north_m, east_m)
        other.send(M.MAVLink_global_position_int_message(0, round(lat * 1e7), round(lon * 1e7),
                                                         round((584.0 + alt_m) * 1000), round(alt_m * 1000),
                                                         0, 0, 0, 0))

    report(0.0, 50.0, 50.0)  # 50 m east, 50 m up: pitch +45 is beyond MNT1_PITCH_MAX (20): held at 20
    hit, last = settled(gcs, 20.0, 90.0)
    assert hit is not None, f"not pointing east and up: {last}"
    report(-50.0, 0.0, 0.0)  # it moves: 50 m south, on the ground
    hit, last = settled(gcs, 0.0, 180.0)
    assert hit is not None, f"did not follow system 7 south: {last}"
