"""MAVLink2 signing against the real daemon, with pymavlink's signing as the client."""

from __future__ import annotations

import hashlib
import time

from gcsd.wire.signing import EPOCH_2015_S, UNITS_PER_S

from .helpers import Client, M, is_ack, pump, udp_channel, udp_url, wait_for

KEY = hashlib.sha256(b"correct horse battery staple").digest()
OTHER_KEY = hashlib.sha256(b"wrong").digest()


def now_units() -> int:
    return int((time.time() - EPOCH_2015_S) * UNITS_PER_S)


def sign(c: Client, key: bytes, link_id: int = 0, timestamp: int | None = None) -> None:
    c.mav.signing.secret_key = key
    c.mav.signing.link_id = link_id
    c.mav.signing.timestamp = timestamp if timestamp is not None else now_units()
    c.mav.signing.sign_outgoing = True


def arm_ack(c: Client, timeout: float = 1.5):
    mark = c.mark()
    c.command_long(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    return wait_for(c, is_ack(M.MAV_CMD_REQUEST_MESSAGE), timeout, since=mark)


def ask(c: Client) -> None:
    c.command_long(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)


def answered_meanwhile(d, station: Client, *refused: Client) -> None:
    """The control for "nothing was accepted": a station with the key, on the same channel (so on
    the same socket queue, after the refused frames), is answered. Any reply to a refused client
    would have been written before that answer, so it is in the client's socket by now."""
    assert arm_ack(station) is not None, "the daemon did not answer a station with the key"
    for c in refused:
        c.read_available()


def wait_stat(d, channel: str, key: str, at_least: int, timeout: float = 3.0) -> int:
    """Poll a channel counter until it reaches at_least (or the timeout); returns its value."""
    deadline = time.monotonic() + timeout
    while (n := d.stats(channel).get(key, 0)) < at_least and time.monotonic() < deadline:
        time.sleep(0.01)
    return n


def keyholder(client, d, channel: str = "gcs") -> Client:
    station = client(udp_url(d.port(channel)), 240, 190)
    sign(station, KEY, link_id=9)
    return station


def answered_request(c: Client) -> bytes:
    """A REQUEST_MESSAGE that is answered: its exact bytes, for a replay."""
    mark = c.mark()
    raw = c.command_long(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert wait_for(c, is_ack(M.MAV_CMD_REQUEST_MESSAGE), since=mark) is not None
    return raw


def signed_daemon(daemon, tmp_path, **channel):
    return daemon({
        "state_dir": str(tmp_path / "st"),
        "signing": {"key": KEY.hex(), "require": True},
        "channels": [udp_channel("gcs", **channel), udp_channel("open", options=["unsigned_ok"])],
    })


def test_signed_client_with_the_key_is_answered_and_replies_are_signed(daemon, client, tmp_path):
    d = signed_daemon(daemon, tmp_path)
    c = client(udp_url(d.port("gcs")))
    sign(c, KEY)
    assert arm_ack(c) is not None
    reply = [r for r in c.received if r.src == (1, 1)][-1]
    assert reply.raw[2] & 0x01, "replies on a signed channel are signed"
    assert hashlib.sha256(KEY + reply.raw[:-6]).digest()[:6] == reply.raw[-6:]


def test_client_without_the_key_gets_nothing_accepted(daemon, client, tmp_path):
    d = signed_daemon(daemon, tmp_path)
    unsigned = client(udp_url(d.port("gcs")), 250, 190)
    wrong = client(udp_url(d.port("gcs")), 251, 190)
    sign(wrong, OTHER_KEY)
    ask(unsigned)
    ask(wrong)
    answered_meanwhile(d, keyholder(client, d), unsigned, wrong)
    assert unsigned.received == [] and wrong.received == []
    stats = d.stats("gcs")
    assert stats["signature_rejects_unsigned"] >= 1 and stats["signature_rejects_bad_signature"] >= 1


def test_rejections_are_explained_to_the_stations_served_by_at_most_one_statustext_per_10_s(daemon, client, tmp_path):
    d = signed_daemon(daemon, tmp_path)
    station = client(udp_url(d.port("gcs")))
    sign(station, KEY)
    assert arm_ack(station) is not None  # served: it has sent a good signed frame
    stranger = client(udp_url(d.port("gcs")), 250, 190)
    mark = station.mark()
    for _ in range(5):
        stranger.heartbeat()
    pump([station, stranger], 2.5)
    texts = [r for r in station.received[mark:] if r.type == "STATUSTEXT" and "Signing" in r.msg.text]
    assert len(texts) == 1 and "unsigned" in texts[0].msg.text
    assert [r for r in station.received[mark:] if r.type == "HEARTBEAT"], "the station kept being served"
    assert stranger.received == [], "a source of rejected frames gets nothing back (no amplification)"


def test_mavlink1_is_refused_on_a_channel_that_requires_signing(daemon, client, tmp_path):
    d = signed_daemon(daemon, tmp_path)
    c = client(udp_url(d.port("gcs")), version=1)
    ask(c)
    answered_meanwhile(d, keyholder(client, d), c)
    assert c.received == []
    assert d.stats("gcs")["signature_rejects_unsigned"] >= 1


def test_unsigned_ok_channel_accepts_unsigned_clients(daemon, client, tmp_path):
    d = signed_daemon(daemon, tmp_path)
    assert arm_ack(client(udp_url(d.port("open")))) is not None


def test_replayed_packet_is_dropped(daemon, client, tmp_path):
    d = signed_daemon(daemon, tmp_path)
    c = client(udp_url(d.port("gcs")))
    sign(c, KEY)
    raw = answered_request(c)
    mark = c.mark()
    c.write(raw)
    c.command_long(M.MAV_CMD_GET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_ATTITUDE)  # fresh, just after: answered
    assert wait_for(c, is_ack(M.MAV_CMD_GET_MESSAGE_INTERVAL), since=mark)
    assert [r for r in c.since(mark) if is_ack(M.MAV_CMD_REQUEST_MESSAGE)(r)] == []
    assert d.stats("gcs")["signature_rejects_replay"] == 1


def test_new_stream_two_minutes_old_is_dropped(daemon, client, tmp_path):
    d = signed_daemon(daemon, tmp_path)
    c = client(udp_url(d.port("gcs")))
    sign(c, KEY, timestamp=now_units() - 120 * UNITS_PER_S)
    ask(c)
    answered_meanwhile(d, keyholder(client, d), c)
    assert c.received == []
    assert d.stats("gcs")["signature_rejects_stale"] >= 1


def test_packets_captured_before_a_restart_are_dropped_after_it(daemon, client, tmp_path):
    d = signed_daemon(daemon, tmp_path)
    c = client(udp_url(d.port("gcs")))
    sign(c, KEY)
    mark = c.mark()
    captured = c.command_long(M.MAV_CMD_REQUEST_MESSAGE, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
    assert wait_for(c, is_ack(M.MAV_CMD_REQUEST_MESSAGE), since=mark)
    d.stop()
    d2 = signed_daemon(daemon, tmp_path)
    attacker = client(udp_url(d2.port("gcs")))
    attacker.write(captured)
    answered_meanwhile(d2, keyholder(client, d2), attacker)
    assert attacker.received == []
    assert d2.stats("gcs")["signature_rejects_replay"] == 1  # at or below the saved timestamp: the floor


def setup_signing(c: Client, key: bytes) -> None:
    c.send(M.MAVLink_setup_signing_message(1, 1, key, now_units()))


def test_setup_signing_on_an_unsigned_ok_channel_enables_signing_everywhere(daemon, client, tmp_path):
    d = daemon({
        "state_dir": str(tmp_path / "st"), "signing": {"require": True},
        "channels": [udp_channel("gcs"), udp_channel("open", options=["unsigned_ok"])],
    })
    gcs = client(udp_url(d.port("gcs")))
    ask(gcs)  # required and no key: nothing is accepted
    trusted = client(udp_url(d.port("open")), 254, 190)
    mark = trusted.mark()
    setup_signing(trusted, KEY)
    assert wait_for(trusted, lambda r: r.type == "STATUSTEXT" and "Signing enabled" in r.msg.text, since=mark)
    assert wait_stat(d, "gcs", "signature_rejects_unsigned", 1) >= 1
    gcs.read_available()
    assert gcs.received == []
    sign(gcs, KEY)
    assert arm_ack(gcs) is not None
    assert (tmp_path / "st" / "signing.key").stat().st_mode & 0o777 == 0o600
    assert KEY.hex() not in (tmp_path / "st").joinpath("mav.parm").read_text()


def test_setup_signing_on_an_unsigned_channel_changes_nothing(daemon, client, tmp_path):
    d = daemon({"state_dir": str(tmp_path / "st"), "channels": [udp_channel("gcs")]})
    c = client(udp_url(d.port("gcs")))
    mark = c.mark()
    setup_signing(c, KEY)
    assert wait_for(c, lambda r: r.type == "STATUSTEXT" and "signed or unsigned_ok" in r.msg.text, since=mark)
    ack = arm_ack(c)
    assert ack is not None and not ack.raw[2] & 0x01, "still unsigned: no key was installed"
    assert not (tmp_path / "st" / "signing.key").exists()


def test_setup_signing_is_refused_while_armed_and_the_sender_is_told(daemon, client, tmp_path):
    d = daemon({"state_dir": str(tmp_path / "st"), "channels": [udp_channel("open", options=["unsigned_ok"])]})
    c = client(udp_url(d.port("open")))
    mark = c.mark()
    c.command_long(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, 21196)
    assert wait_for(c, is_ack(M.MAV_CMD_COMPONENT_ARM_DISARM), since=mark).msg.result == M.MAV_RESULT_ACCEPTED
    mark = c.mark()
    setup_signing(c, KEY)
    assert wait_for(c, lambda r: r.type == "STATUSTEXT" and "armed" in r.msg.text, since=mark)
    assert not (tmp_path / "st" / "signing.key").exists()


def test_radio_status_is_accepted_unsigned(daemon, client, tmp_path):
    d = signed_daemon(daemon, tmp_path)
    c = client(udp_url(d.port("gcs")), 51, 68)
    c.send(M.MAVLink_radio_status_message(200, 200, 40, 0, 0, 0, 0))
    ask(c)  # the control, just after on the same socket: an unsigned command is counted as a reject
    assert wait_stat(d, "gcs", "signature_rejects_unsigned", 1) == 1, "the command only, not RADIO_STATUS"


def test_forwarded_frames_keep_their_signature(daemon, client, tmp_path):
    d = daemon({
        "state_dir": str(tmp_path / "st"), "signing": {"key": KEY.hex()},
        "channels": [udp_channel("a"), udp_channel("b")],
    })
    a = client(udp_url(d.port("a")), 255, 190)
    b = client(udp_url(d.port("b")), 77, 1)
    sign(a, KEY, link_id=3)
    sign(b, KEY, link_id=4)
    b.heartbeat(M.MAV_TYPE_ONBOARD_CONTROLLER)
    a.heartbeat()
    # a UDP server answers only a peer it has read: b's heartbeat (and so its route) is in
    for c in (a, b):
        assert wait_for(c, lambda r: r.src == (1, 1), others=[a, b]), "a station's heartbeat was not read"
    mark = b.mark()
    raw = a.command_long(M.MAV_CMD_REQUEST_MESSAGE, 1, target=(77, 1))
    got = wait_for(b, lambda r: r.raw == raw, since=mark)
    assert got is not None and got.raw[-13] == 3, "byte-exact, link id and signature of the sender"
