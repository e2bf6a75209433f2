"""A swarm of 20 simulated vehicles behind one UDP server (`vehicle.count: 20`).

One ground-station socket hears 20 systems (sysids 1..20, each its own HEARTBEAT and
position); each vehicle answers only for its own sysid: a parameter set on vehicle 7 changes
vehicle 7 alone (PARAM_VALUE from 7 only, the others still read the default), a command to
vehicle 3 arms vehicle 3 alone, and every vehicle has its own state directory.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as M

from .helpers import pump, udp_channel, udp_url, wait_for

COUNT = 20


def _name(raw) -> str:
    return (raw.decode() if isinstance(raw, bytes) else raw).rstrip("\0")


def test_one_udp_server_shows_twenty_systems_and_each_answers_only_for_itself(daemon, client, tmp_path):
    d = daemon({"vehicle": {"count": COUNT}, "channels": [udp_channel("gcs")]})
    gcs = client(udp_url(d.port("gcs")))
    gcs.heartbeat()
    pump([gcs], 2.5)
    systems = {r.src[0] for r in gcs.since(0, "HEARTBEAT")}
    assert systems == set(range(1, COUNT + 1))
    positions = {r.src[0]: (r.msg.lat, r.msg.lon) for r in gcs.since(0, "GLOBAL_POSITION_INT")}
    assert len(set(positions.values())) == COUNT  # each starts on its own spot

    mark = gcs.mark()
    gcs.send(M.MAVLink_param_set_message(7, 1, b"WPNAV_SPEED", 777.0, M.MAV_PARAM_TYPE_REAL32))
    echo = wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and _name(r.msg.param_id) == "WPNAV_SPEED", 3.0, mark)
    assert echo is not None and echo.src == (7, 1) and echo.msg.param_value == 777.0
    pump([gcs], 0.5)
    assert {r.src for r in gcs.since(mark, "PARAM_VALUE")} == {(7, 1)}
    for sysid in (6, 7, 8):
        mark = gcs.mark()
        gcs.send(M.MAVLink_param_request_read_message(sysid, 1, b"WPNAV_SPEED", -1))
        value = wait_for(gcs, lambda r, s=sysid: r.type == "PARAM_VALUE" and r.src == (s, 1), 3.0, mark)
        assert value is not None and value.msg.param_value == (777.0 if sysid == 7 else 1000.0)  # ArduCopter SITL default

    mark = gcs.mark()
    gcs.command_long(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=(3, 1))
    ack = wait_for(gcs, lambda r: r.type == "COMMAND_ACK" and r.msg.command == M.MAV_CMD_COMPONENT_ARM_DISARM, 3.0, mark)
    assert ack is not None and ack.src == (3, 1) and ack.msg.result == M.MAV_RESULT_ACCEPTED
    pump([gcs], 1.5)
    armed = {r.src[0] for r in gcs.since(mark, "HEARTBEAT") if r.msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED}
    assert armed == {3}
    assert (tmp_path / "state" / "vehicle-7" / "mav.parm").read_text().count("WPNAV_SPEED") == 1
    assert "WPNAV_SPEED" not in (tmp_path / "state" / "vehicle-8" / "mav.parm").read_text()
