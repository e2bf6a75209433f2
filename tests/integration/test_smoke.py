from pymavlink import mavutil


def test_daemon_answers_a_ground_station_with_a_heartbeat(daemon):
    d = daemon({"channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]})
    gcs = mavutil.mavlink_connection(f"udpout:127.0.0.1:{d.port('gcs')}", source_system=255)
    try:
        gcs.mav.heartbeat_send(6, 8, 0, 0, 0)
        hb = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=3)
        assert hb is not None
        assert (hb.get_srcSystem(), hb.get_srcComponent()) == (1, 1)
        assert hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
        assert hb.type == mavutil.mavlink.MAV_TYPE_QUADROTOR
    finally:
        gcs.close()
