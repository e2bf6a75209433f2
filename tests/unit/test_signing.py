"""MAVLink2 signing core: signatures, streams, the one-minute window, restart safety."""

import os

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.signing import (
    BAD_SIGNATURE, FUTURE, FUTURE_LIMIT_S, MAX_STREAMS, NO_KEY, REPLAY, STALE, UNITS_PER_S, UNSIGNED,
    SavedSigning, Signing, SigningManager, SigningStore, wall_to_units,
)

KEY = bytes(range(32))
WALL = 1_800_000_000.0
NOW = wall_to_units(WALL)


def signed_frame(key=KEY, timestamp=NOW, link_id=0, sysid=255, compid=190, msg=None) -> bytes:
    mav = M.MAVLink(None, srcSystem=sysid, srcComponent=compid)
    mav.signing.secret_key, mav.signing.link_id, mav.signing.timestamp = key, link_id, timestamp
    mav.signing.sign_outgoing = True
    msg = msg or M.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    return bytes(msg.pack(mav))


def unsigned_frame(msg=None, v1=False) -> bytes:
    mav = M.MAVLink(None, srcSystem=255, srcComponent=190)
    msg = msg or M.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    return bytes(msg.pack(mav, force_mavlink1=v1))


def check(s: Signing, raw: bytes, unsigned_ok=False, msgid=76):
    return s.check(raw, msgid, 255, 190, unsigned_ok)


def test_good_signature_is_accepted_and_raises_local_timestamp():
    s = Signing(KEY, NOW)
    assert check(s, signed_frame(timestamp=NOW + 500)) is None
    assert s.timestamp == NOW + 500


def test_wrong_key_is_refused():
    assert check(Signing(KEY, NOW), signed_frame(key=bytes(32 * [7]))) == BAD_SIGNATURE


def test_replayed_frame_is_refused():
    s = Signing(KEY, NOW)
    raw = signed_frame()
    assert check(s, raw) is None
    assert check(s, raw) == REPLAY


def test_new_stream_two_minutes_old_is_refused_within_a_minute_accepted():
    s = Signing(KEY, NOW)
    assert check(s, signed_frame(timestamp=NOW - 120 * UNITS_PER_S)) == STALE
    assert check(s, signed_frame(timestamp=NOW - 30 * UNITS_PER_S, link_id=1)) is None


def test_streams_are_per_link_id():
    s = Signing(KEY, NOW)
    assert check(s, signed_frame(timestamp=NOW + 10, link_id=0)) is None
    assert check(s, signed_frame(timestamp=NOW + 5, link_id=1)) is None


def test_unsigned_frames_when_required_are_refused_except_radio_status_and_unsigned_ok():
    s = Signing(KEY, NOW, require=True)
    assert check(s, unsigned_frame()) == UNSIGNED
    assert check(s, unsigned_frame(v1=True)) == UNSIGNED
    assert check(s, unsigned_frame(), unsigned_ok=True) is None
    radio = M.MAVLink_radio_status_message(0, 0, 50, 0, 0, 0, 0)
    assert check(s, unsigned_frame(radio), msgid=109) is None


def test_unsigned_frames_are_accepted_when_not_required():
    assert check(Signing(KEY, NOW, require=False), unsigned_frame()) is None


def test_signed_frame_without_a_key_is_refused_only_when_required():
    assert check(Signing(None, NOW, require=True), signed_frame()) == NO_KEY
    assert check(Signing(None, NOW, require=False), signed_frame()) is None


def test_all_zero_key_turns_signing_off():
    s = Signing(KEY, NOW)
    s.set_key(bytes(32))
    assert s.key is None and not s.checks_needed


def test_outgoing_timestamps_never_go_back():
    s = Signing(KEY, NOW + 10 * UNITS_PER_S)
    first = s.next_timestamp(WALL)
    assert s.next_timestamp(WALL) == first + 1
    assert s.next_timestamp(WALL + 100) == wall_to_units(WALL + 100)


def test_store_keeps_key_and_timestamp_with_private_permissions(tmp_path):
    store = SigningStore(tmp_path / "signing.key")
    store.save(KEY, NOW, clean=True)
    assert store.load() == SavedSigning(KEY, NOW, True)
    assert os.stat(tmp_path / "signing.key").st_mode & 0o777 == 0o600


def test_restart_puts_every_frame_seen_before_it_outside_the_window(tmp_path):
    store = SigningStore(tmp_path / "signing.key")
    before = Signing(KEY, NOW)
    captured = signed_frame(timestamp=NOW + 1000)
    assert check(before, captured) is None
    store.save(before.key, before.timestamp, clean=True)
    after = SigningManager(None, False, store, WALL).signing
    assert check(after, captured) == STALE


def test_unclean_stop_advances_further_than_the_save_interval(tmp_path):
    store = SigningStore(tmp_path / "signing.key")
    store.save(KEY, NOW, clean=False)
    after = SigningManager(None, False, store, WALL).signing
    # a frame up to one save interval newer than the saved timestamp may have been accepted before
    assert check(after, signed_frame(timestamp=NOW + 9 * UNITS_PER_S)) == STALE


def test_configured_key_wins_over_the_saved_one(tmp_path):
    store = SigningStore(tmp_path / "signing.key")
    store.save(bytes(32 * [9]), NOW, clean=True)
    assert SigningManager(KEY, False, store, WALL).signing.key == KEY
    assert SigningManager(None, False, store, WALL).signing.key == bytes(32 * [9])


def test_manager_warns_at_most_once_per_ten_seconds_per_channel(tmp_path):
    m = SigningManager(None, False, None, WALL)
    assert [m.should_warn(0, t) for t in (0.0, 5.0, 10.5)] == [True, False, True]
    assert m.should_warn(1, 5.0)


def test_unsigned_ok_channel_accepts_a_frame_signed_with_a_wrong_key_as_unsigned():
    s = Signing(KEY, NOW, require=True)
    assert check(s, signed_frame(key=bytes(32 * [7])), unsigned_ok=True) is None
    assert check(s, signed_frame(key=bytes(32 * [7]))) == BAD_SIGNATURE


def test_a_valid_signature_on_an_unsigned_ok_channel_still_advances_the_stream():
    s = Signing(KEY, NOW)
    raw = signed_frame(timestamp=NOW + 50)
    assert check(s, raw, unsigned_ok=True) is None
    assert s.timestamp == NOW + 50
    assert check(s, raw) == REPLAY


def test_a_stream_forgotten_when_the_table_is_full_cannot_be_replayed():
    s = Signing(KEY, NOW)
    captured = signed_frame(timestamp=NOW + 1, link_id=0)
    assert check(s, captured) is None
    for i in range(1, MAX_STREAMS + 6):  # more new streams than the table holds, all later
        assert s.check(signed_frame(timestamp=NOW + 10 + i, link_id=i % 256, sysid=200 + i // 256), 76,
                       200 + i // 256, 190, False) is None
    assert check(s, captured) == REPLAY
    assert check(s, signed_frame(timestamp=NOW + 1000, link_id=0)) is None, "the stream itself may come back"


def test_a_timestamp_more_than_five_minutes_ahead_of_the_wall_clock_is_refused_and_changes_nothing():
    s = Signing(KEY, NOW)
    ahead = signed_frame(timestamp=wall_to_units(WALL + FUTURE_LIMIT_S + 1))
    assert s.check(ahead, 76, 255, 190, False, WALL) == FUTURE
    assert s.timestamp == NOW
    near = signed_frame(timestamp=wall_to_units(WALL + FUTURE_LIMIT_S - 1), link_id=1)
    assert s.check(near, 76, 255, 190, False, WALL) is None


def test_the_future_limit_is_not_applied_while_the_wall_clock_is_not_set():
    s = Signing(KEY, NOW)
    assert s.check(signed_frame(timestamp=NOW + 10 * 365 * 86400 * UNITS_PER_S), 76, 255, 190, False, 1000.0) is None
