"""MAVLink2 signing core: signatures, streams, the one-minute window, restart safety."""

import os

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.wire.signing import (
    BAD_SIGNATURE,
    FUTURE,
    FUTURE_LIMIT_S,
    MAX_STREAMS,
    MAX_TIMESTAMP,
    NO_KEY,
    REPLAY,
    STALE,
    UNITS_PER_S,
    UNSIGNED,
    SavedSigning,
    Signing,
    SigningManager,
    SigningStore,
    wall_to_units,
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
    s.set_key(bytes(32), 0, WALL)
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


def test_restart_refuses_every_frame_seen_before_it(tmp_path):
    store = SigningStore(tmp_path / "signing.key")
    before = Signing(KEY, NOW)
    captured = signed_frame(timestamp=NOW + 1000)
    assert check(before, captured) is None
    store.save(before.key, before.timestamp, clean=True)
    after = SigningManager(None, False, store, WALL).signing
    assert check(after, captured) == REPLAY
    assert check(after, signed_frame(timestamp=NOW + 1001)) is None  # the same station, its next frame


def test_unclean_stop_refuses_up_to_one_save_interval_past_the_saved_timestamp(tmp_path):
    store = SigningStore(tmp_path / "signing.key")
    store.save(KEY, NOW, clean=False)
    after = SigningManager(None, False, store, WALL).signing
    # a frame up to one save interval newer than the saved timestamp may have been accepted before
    assert check(after, signed_frame(timestamp=NOW + 9 * UNITS_PER_S)) == REPLAY
    assert check(after, signed_frame(timestamp=NOW + 11 * UNITS_PER_S)) is None


def test_restarts_in_quick_succession_never_lock_out_a_station_with_a_true_clock(tmp_path):
    """Found by tests/stateful: each start set the local timestamp 60 s past the saved one, which the
    next clean stop saved, so the second restart within a minute made a true clock `stale`."""
    store = SigningStore(tmp_path / "signing.key")
    store.save(KEY, NOW, clean=True)
    wall = WALL
    for restart in range(5):
        wall += 2.0  # each start two seconds after the last
        m = SigningManager(None, True, store, wall)
        station = signed_frame(timestamp=wall_to_units(wall), link_id=restart)
        assert m.signing.check(station, 76, 255, 190, False, wall) is None, f"refused after restart {restart}"
        m.signing.next_timestamp(wall)  # a reply signed
        m.save(clean=True)
    after = SigningManager(None, True, store, wall).signing
    assert after.check(station, 76, 255, 190, False, wall) == REPLAY  # the last run's frame, replayed


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


# --- SETUP_SIGNING's initial timestamp (issue 17, items 4 and 5) ----------------------------------

def test_setup_with_a_timestamp_a_day_ahead_is_not_taken_so_a_correct_station_is_still_accepted():
    s = Signing(None, NOW)
    s.set_key(KEY, wall_to_units(WALL + 86400), WALL)
    assert s.timestamp == NOW, "beyond the future limit, as a frame would be refused: the wall clock"
    assert s.check(signed_frame(timestamp=NOW + 5), 76, 255, 190, False, WALL) is None
    s.set_key(KEY, wall_to_units(WALL + FUTURE_LIMIT_S - 1), WALL)  # within the limit: taken
    assert s.timestamp == wall_to_units(WALL + FUTURE_LIMIT_S - 1)


def test_a_later_setup_assigns_the_timestamp_so_it_repairs_a_wrong_one():
    s = Signing(None, NOW)
    s.set_key(KEY, wall_to_units(WALL + FUTURE_LIMIT_S - 1), WALL)
    assert check(s, signed_frame(timestamp=NOW + 10)) == STALE
    s.set_key(KEY, NOW, WALL)
    assert s.timestamp == NOW
    assert check(s, signed_frame(timestamp=NOW + 10, link_id=1)) is None


def test_setup_never_puts_the_timestamp_below_the_wall_clock():
    s = Signing(None, 0)
    s.set_key(KEY, 0, WALL)
    assert s.timestamp == NOW


def test_setup_again_with_the_same_key_reopens_no_replay():
    s = Signing(KEY, NOW)
    captured = signed_frame(timestamp=NOW + 100)
    assert check(s, captured) is None
    s.set_key(KEY, NOW, WALL)
    assert check(s, captured) == REPLAY
    s.set_key(bytes(32 * [3]), NOW, WALL)  # positive control: a new key forgets the streams
    assert s.check(signed_frame(key=bytes(32 * [3]), timestamp=NOW + 100), 76, 255, 190, False) is None


def test_setup_with_the_largest_uint64_timestamp_keeps_every_send_inside_48_bits():
    s = Signing(None, NOW)
    s.set_key(KEY, 2**64 - 1, WALL)
    assert s.timestamp == NOW
    unset = Signing(None, 0)  # no wall clock to judge by: the 48-bit field still bounds it
    unset.set_key(KEY, 2**64 - 1, 1000.0)
    assert unset.timestamp == 0
    unset.set_key(KEY, MAX_TIMESTAMP, 1000.0)
    assert [unset.next_timestamp(1000.0) for _ in range(3)] == [MAX_TIMESTAMP] * 3, "stops at the top"
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.signing.secret_key, mav.signing.link_id, mav.signing.sign_outgoing = KEY, 0, True
    mav.signing.timestamp = unset.next_timestamp(1000.0)
    assert M.MAVLink_heartbeat_message(2, 3, 0, 0, 0, 3).pack(mav)  # packs: no struct.error


def test_a_saved_timestamp_beyond_the_bound_is_repaired_at_load(tmp_path):
    store = SigningStore(tmp_path / "signing.key")
    for bad in (wall_to_units(WALL + 86400), 2**64 - 1):
        store.save(KEY, bad, clean=True)
        m = SigningManager(None, False, store, WALL)
        assert m.load_repair is not None
        assert m.signing.timestamp <= wall_to_units(WALL + 120)
        assert m.signing.check(signed_frame(timestamp=NOW + 70 * UNITS_PER_S), 76, 255, 190, False, WALL) is None
    store.save(KEY, NOW + 100 * UNITS_PER_S, clean=True)  # positive control: within bounds, kept
    m = SigningManager(None, False, store, WALL)
    assert m.load_repair is None and m.signing.timestamp == NOW + 100 * UNITS_PER_S


def test_a_frame_at_or_below_the_saved_timestamp_is_refused_after_a_restart_whatever_setup_follows(tmp_path):
    store = SigningStore(tmp_path / "signing.key")
    store.save(KEY, NOW, clean=True)
    m = SigningManager(None, False, store, WALL)
    m.signing.set_key(KEY, NOW - 30 * UNITS_PER_S, WALL)  # the same key, a lower timestamp
    assert check(m.signing, signed_frame(timestamp=NOW)) == REPLAY
    assert check(m.signing, signed_frame(timestamp=NOW + 1, link_id=2)) is None


def test_the_periodic_timestamp_save_is_a_write_behind_source(tmp_path):
    """The snapshot is taken on the loop (take_persist) and written elsewhere; nothing is due
    until the timestamp moves; a failed write makes it due again."""
    store = SigningStore(tmp_path / "signing.key")
    manager = SigningManager(KEY, False, store, 1.8e9)
    manager.save(clean=False)
    assert manager.persist_deadline() is None and manager.take_persist(0.0, force=True) is None
    manager.signing.next_timestamp(1.8e9 + 5)
    assert manager.persist_deadline() == 0.0
    text = manager.take_persist(0.0)
    assert f"timestamp {manager.signing.timestamp}" in text and "clean 0" in text and KEY.hex() in text
    assert manager.persist_deadline() is None, "taken: not due again until it moves"
    manager.persist_failed("disk full")
    assert manager.persist_deadline() == 0.0 and manager.save_error == "disk full"
    SigningStore.write(store.path, manager.take_persist(0.0))
    manager.persist_done()
    assert store.load().timestamp == manager.signing.timestamp and manager.save_error is None
    assert oct(store.path.stat().st_mode & 0o777) == "0o600"
