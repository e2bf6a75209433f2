"""A swarm of 20 simulated vehicles behind one UDP server (`vehicle.count: 20`).

One ground-station socket hears 20 systems (sysids 1..20, each its own HEARTBEAT and
position); each vehicle answers only for its own sysid: a parameter set on vehicle 7 changes
vehicle 7 alone (PARAM_VALUE from 7 only, the others still read the default), a command to
vehicle 3 arms vehicle 3 alone, and every vehicle has its own state directory.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as M

from .helpers import pump, pump_until, udp_channel, udp_url, wait_for

COUNT = 20


def _name(raw) -> str:
    return (raw.decode() if isinstance(raw, bytes) else raw).rstrip("\0")


def test_one_udp_server_shows_twenty_systems_and_each_answers_only_for_itself(daemon, client, tmp_path):
    d = daemon({"vehicle": {"count": COUNT}, "channels": [udp_channel("gcs")]})
    gcs = client(udp_url(d.port("gcs")))
    gcs.heartbeat()
    everyone = set(range(1, COUNT + 1))

    def sources(kind: str) -> set[int]:
        return {r.src[0] for r in gcs.since(0, kind)}

    # 2.5 s (two HEARTBEATs of each), and on until all twenty were heard, however loaded the machine
    pump_until([gcs], lambda: sources("HEARTBEAT") >= everyone and sources("GLOBAL_POSITION_INT") >= everyone,
               at_least_s=2.5)
    assert sources("HEARTBEAT") == everyone
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
    after = gcs.mark()

    def armed() -> set[int]:
        return {r.src[0] for r in gcs.since(mark, "HEARTBEAT") if r.msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED}

    # until vehicle 3 shows itself armed and every vehicle has sent a HEARTBEAT since the ACK
    pump_until([gcs], lambda: 3 in armed() and {r.src[0] for r in gcs.since(after, "HEARTBEAT")} >= everyone,
               at_least_s=1.5)
    assert armed() == {3}
    assert (tmp_path / "state" / "vehicle-7" / "mav.parm").read_text().count("WPNAV_SPEED") == 1
    assert "WPNAV_SPEED" not in (tmp_path / "state" / "vehicle-8" / "mav.parm").read_text()


def _heartbeat_sysids(gcs, expected: set[int], seconds: float = 2.5) -> set[int]:
    """The systems heard in `seconds` (two HEARTBEATs of each), or until `expected` were all heard."""
    gcs.heartbeat()
    mark = gcs.mark()
    pump_until([gcs], lambda: {r.src[0] for r in gcs.since(mark, "HEARTBEAT")} >= expected, at_least_s=seconds)
    return {r.src[0] for r in gcs.since(mark, "HEARTBEAT")}


def _set(gcs, sysid: int, name: str, value: float, text: str | None = None):
    """PARAM_SET to a vehicle: its PARAM_VALUE answer and its STATUSTEXTs meanwhile; with `text`,
    until a STATUSTEXT containing it has come (it may follow the answer)."""
    mark = gcs.mark()
    gcs.send(M.MAVLink_param_set_message(sysid, 1, name.encode(), value, M.MAV_PARAM_TYPE_REAL32))
    echo = wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and _name(r.msg.param_id) == name, 3.0, mark)
    if text is not None:
        wait_for(gcs, lambda r: r.type == "STATUSTEXT" and r.src == (sysid, 1) and text in r.msg.text, 3.0, mark)
    return echo, [r.msg.text for r in gcs.since(mark, "STATUSTEXT") if r.src == (sysid, 1)]


def test_a_swarm_refuses_a_sysid_another_vehicle_has_and_a_saved_clash_falls_back(daemon, client, tmp_path, capfd):
    """Issue 17, item 9: SYSID_THISMAV 2 on vehicle 1 of three used to be taken, and after a
    restart two vehicles answered as 2 and vehicle 1 was gone."""
    conf = {"vehicle": {"count": 3}, "state_dir": str(tmp_path / "st"), "channels": [udp_channel("gcs")]}
    d = daemon(conf)
    gcs = client(udp_url(d.port("gcs")))
    assert _heartbeat_sysids(gcs, {1, 2, 3}) == {1, 2, 3}
    echo, texts = _set(gcs, 1, "SYSID_THISMAV", 2.0, text="refused")
    assert echo.src == (1, 1) and echo.msg.param_value == 1.0, "refused: the old value back"
    assert "SYSID_THISMAV 2 refused: another vehicle's sysid" in texts
    echo, _ = _set(gcs, 3, "SYSID_THISMAV", 7.0)  # the control: a free sysid is taken (next start)
    assert echo.src == (3, 1) and echo.msg.param_value == 7.0
    echo, texts = _set(gcs, 1, "SYSID_THISMAV", 7.0, text="refused")  # vehicle 3's from its next start
    assert echo.msg.param_value == 1.0 and any("refused" in t for t in texts)
    echo, _ = _set(gcs, 1, "WPNAV_SPEED", 777.0)
    assert echo.msg.param_value == 777.0
    d.stop()

    d = daemon(conf)
    gcs = client(udp_url(d.port("gcs")))
    assert _heartbeat_sysids(gcs, {1, 2, 7}) == {1, 2, 7}
    d.stop()
    saved = tmp_path / "st" / "vehicle-1" / "mav.parm"  # a clash saved by an older gcsd
    saved.write_text(saved.read_text() + "SYSID_THISMAV 2\n")
    capfd.readouterr()
    d = daemon(conf)
    gcs = client(udp_url(d.port("gcs")))
    assert _heartbeat_sysids(gcs, {1, 2, 7}) == {1, 2, 7}, "vehicle 1 falls back to its configured sysid"
    assert "sysid_fallback" in capfd.readouterr().out
    mark = gcs.mark()
    gcs.send(M.MAVLink_param_request_read_message(1, 1, b"WPNAV_SPEED", -1))
    kept = wait_for(gcs, lambda r: r.type == "PARAM_VALUE" and r.src == (1, 1), 3.0, mark)
    assert kept is not None and kept.msg.param_value == 777.0, "nothing else of vehicle 1 is lost"
