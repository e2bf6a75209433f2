"""MAVLink2 message signing (REFERENCE.md section 9): the pure core. Wall time comes in as `wall_s`.

Timestamps are 48-bit, in 10 us units since 2015-01-01. Our local timestamp never goes back:
it is at least the wall clock, it rises with every packet we sign, and with every valid packet
we accept.

Incoming, per frame (`check`):
- Signed frame and a key: the signature (first 6 bytes of SHA-256(key + frame without its
  signature)) must match. Streams are keyed by (sysid, compid, link id). A new stream is
  accepted only if its timestamp is at most 60 s behind our local timestamp; a known stream's
  timestamp must strictly increase. At most MAX_STREAMS streams are tracked; when full, the
  stream seen least recently is forgotten (ArduPilot refuses new streams instead, which locks
  out a ground station that reconnects with a new link id), and its last timestamp raises a
  floor: a stream not in the table is accepted only above the floor, so forgetting a stream
  never reopens its replays, however many streams come and go.
- A timestamp more than FUTURE_LIMIT_S ahead of the local wall clock is refused (`future`) and
  changes nothing: otherwise one validly signed frame from a ground station with a wrong clock
  would raise our timestamp (and the saved one) and lock every other station out, across
  restarts too. Five minutes covers ordinary clock skew between a ground station and a
  companion computer. The check is skipped while the local wall clock is before
  SANE_WALL_CLOCK_S (a board without a real-time clock that has not synced yet cannot judge).
- Unsigned frame (MAVLink1 included): RADIO_STATUS and RADIO are always accepted; on a channel
  marked unsigned_ok it is accepted; otherwise it is refused when `require` is set, and accepted
  when it is not (SPEC.md: `require: false` is the permissive default).
- Signed frame but no key: refused when `require` is set (it cannot be checked), else accepted.
- On an unsigned_ok channel (a trusted link) a signed frame that fails these checks is accepted
  as if it were unsigned, as ArduPilot does on its USB channel: unsigned frames are accepted
  there anyway, and a ground station whose key got out of step (MAVProxy switches keys even
  when a SETUP_SIGNING is refused) must not be locked out of the one link meant to fix it.

Several keys (SPEC.md "Authority", `signing.keys`): a signed frame is checked against the key its
stream (sysid, compid, link id) verified with last, and only if that fails against the others,
so a station costs one HMAC per frame however many keys are configured. `verified_by` is the
StationKey of the last accepted signed frame (the vehicle's own key: VEHICLE_KEY_NAME, role
admin), None for a frame accepted unsigned; `set_keys` replaces the station keys at once (a
revoked key's next frame is refused) and forgets which stream used which.

Outgoing: `next_timestamp()` for each packet signed on a channel whose output is MAVLink2. It
never passes MAX_TIMESTAMP (the 48-bit field's largest value), so no send can fail on it.

SETUP_SIGNING (`set_key`) assigns the local timestamp as ArduPilot does (a later setup repairs a
wrong one), checked as an incoming frame's timestamp is checked: one more than FUTURE_LIMIT_S
ahead of the wall clock (while the wall clock is set), or past MAX_TIMESTAMP, is not taken and
the wall clock is used instead, as a frame that far ahead would change nothing; never below the
wall clock. A new key forgets every stream; the same key again keeps the stream table and the floor,
so lowering the timestamp reopens no replay.

Restart safety: the timestamp is saved (see SigningStore) every SAVE_INTERVAL_S and at a clean
stop. At start the saved timestamp, plus SAVE_INTERVAL_S when the last stop was not clean, is the
floor for new streams (a frame at or below it is one the last run may have accepted): a replay
across a restart is always refused. The local timestamp starts at the floor or the wall clock,
whichever is later, and no further ahead: a start that pushed it 60 s past the saved one would
have it saved that far ahead at the next stop, so two restarts within a minute made every ground
station with a true clock `stale` for a minute per restart (found by tests/stateful). A saved timestamp beyond the bound
above (written by an older version, or by a ground station's wrong clock) is repaired at load:
the wall clock replaces it, and `load_repair` says so for the log.
"""

from __future__ import annotations

import hashlib
import hmac
from dataclasses import dataclass, field
from pathlib import Path

from gcsd.atomic import write_atomic
from gcsd.wire.msgids import is_radio

EPOCH_2015_S = 1420070400
UNITS_PER_S = 100_000
WINDOW_UNITS = 60 * UNITS_PER_S
MAX_STREAMS = 64
SAVE_INTERVAL_S = 10.0
MAX_TIMESTAMP = (1 << 48) - 1  # the signature's timestamp field is 48 bits
SIG_LEN = 13  # link id 1 + timestamp 6 + signature 6
FUTURE_LIMIT_S = 300.0
SANE_WALL_CLOCK_S = 1735689600  # 2025-01-01: a wall clock before this is not set

# rejection reasons, also the counter names
UNSIGNED = "unsigned"
BAD_SIGNATURE = "bad_signature"
REPLAY = "replay"
STALE = "stale"
NO_KEY = "no_key"
FUTURE = "future"


def wall_to_units(wall_s: float) -> int:
    return max(0, int((wall_s - EPOCH_2015_S) * UNITS_PER_S))


def timestamp_in_bounds(timestamp: int, wall_s: float) -> bool:
    """Whether a timestamp from outside (SETUP_SIGNING, the saved file) may be taken: bounded as a
    frame's is (not more than FUTURE_LIMIT_S ahead of a wall clock that is set) and within the
    48-bit field."""
    if wall_s >= SANE_WALL_CLOCK_S and timestamp > wall_to_units(wall_s + FUTURE_LIMIT_S):
        return False
    return 0 <= timestamp <= MAX_TIMESTAMP


VEHICLE_KEY_NAME = "vehicle"
ADMIN_ROLE = 2  # routing/authority.py's ADMIN: the vehicle's own key may do everything


@dataclass(frozen=True, slots=True)
class StationKey:
    """A named key and the role (routing/authority.py's integer) a frame signed with it gets."""

    name: str
    key: bytes = field(repr=False)
    role: int


def signature_of(key: bytes, frame_without_signature: bytes) -> bytes:
    return hashlib.sha256(key + frame_without_signature).digest()[:6]


class Signing:
    def __init__(self, key: bytes | None = None, timestamp: int = 0, require: bool = False, floor: int = 0) -> None:
        self.key = key
        self.timestamp = min(timestamp, MAX_TIMESTAMP)
        self.require = require
        self._streams: dict[tuple[int, int, int], int] = {}
        self._floor = floor  # a new stream must be above it: a forgotten stream's last, the saved one
        self.station_keys: tuple[StationKey, ...] = ()
        self._all_keys: tuple[StationKey, ...] = ()  # the vehicle's key first, then the stations'
        self._stream_keys: dict[tuple[int, int, int], StationKey] = {}
        self.verified_by: StationKey | None = None
        self._rebuild_keys()

    @property
    def checks_needed(self) -> bool:
        """False when every frame is accepted untouched (no key, not required): the fast path."""
        return self.key is not None or self.require or bool(self.station_keys)

    def set_keys(self, keys: tuple[StationKey, ...]) -> None:
        """The station keys (signing.keys, `gcsd keys`), in force from the next frame."""
        self.station_keys = tuple(keys)
        self._rebuild_keys()

    def _rebuild_keys(self) -> None:
        own = () if self.key is None else (StationKey(VEHICLE_KEY_NAME, self.key, ADMIN_ROLE),)
        self._all_keys = own + self.station_keys
        self._stream_keys.clear()

    def set_key(self, key: bytes | None, timestamp: int, wall_s: float) -> None:
        """SETUP_SIGNING: the key (None or 32 zero bytes: signing off) and the timestamp, assigned
        within the bounds. A different key forgets the known streams; the same key keeps them."""
        key = None if key is None or key == bytes(32) else bytes(key)
        if key != self.key:
            self._streams.clear()
            self._floor = 0
        self.key = key
        self._rebuild_keys()
        taken = timestamp if timestamp_in_bounds(timestamp, wall_s) else 0
        self.timestamp = min(MAX_TIMESTAMP, max(wall_to_units(wall_s), taken))

    def next_timestamp(self, wall_s: float) -> int:
        self.timestamp = min(MAX_TIMESTAMP, max(self.timestamp + 1, wall_to_units(wall_s)))
        return self.timestamp

    def check(self, raw: bytes, msgid: int, sysid: int, compid: int, unsigned_ok: bool,
              wall_s: float = 0.0) -> str | None:
        """None if the frame is accepted, else the reason it is refused. Only an accepted frame
        changes state (the stream table and the local timestamp)."""
        self.verified_by = None
        signed = raw[0] == 0xFD and raw[2] & 0x01
        if not signed:
            if unsigned_ok or is_radio(msgid):
                return None
            return UNSIGNED if self.require else None
        reason = self._check_signed(raw, sysid, compid, wall_s)
        if reason is not None:
            self.verified_by = None
            return None if unsigned_ok else reason
        return None

    def _verifying_key(self, raw: bytes, stream: tuple[int, int, int]) -> StationKey | None:
        """The key this frame is signed with: its stream's last first, then the others."""
        body, signature = raw[:-6], raw[-6:]
        known = self._stream_keys.get(stream)
        if known is not None and hmac.compare_digest(signature_of(known.key, body), signature):
            return known
        for candidate in self._all_keys:
            if candidate is not known and hmac.compare_digest(signature_of(candidate.key, body), signature):
                return candidate
        return None

    def _check_signed(self, raw: bytes, sysid: int, compid: int, wall_s: float) -> str | None:
        if not self._all_keys:
            return NO_KEY if self.require else None
        link_id = raw[-SIG_LEN]
        stream = (sysid, compid, link_id)
        if self.station_keys:
            verified = self._verifying_key(raw, stream)
            if verified is None:
                return BAD_SIGNATURE
        else:
            verified = self._all_keys[0]
            if not hmac.compare_digest(signature_of(verified.key, raw[:-6]), raw[-6:]):
                return BAD_SIGNATURE
        ts = int.from_bytes(raw[-12:-6], "little")
        if wall_s >= SANE_WALL_CLOCK_S and ts > wall_to_units(wall_s + FUTURE_LIMIT_S):
            return FUTURE
        last = self._streams.get(stream)
        if last is None:
            if ts + WINDOW_UNITS < self.timestamp:
                return STALE
            if ts <= self._floor:
                return REPLAY  # not above a stream we had to forget (or the saved timestamp)
            if len(self._streams) >= MAX_STREAMS:
                oldest = min(self._streams, key=self._streams.get)
                self._floor = max(self._floor, self._streams.pop(oldest))
        elif ts <= last:
            return REPLAY
        self._streams[stream] = ts
        if self.station_keys and self._stream_keys.get(stream) is not verified:
            if len(self._stream_keys) >= MAX_STREAMS * 4:
                self._stream_keys.clear()  # a memo only: rebuilt by the next frames
            self._stream_keys[stream] = verified
        self.timestamp = max(self.timestamp, ts)
        self.verified_by = verified
        return None


@dataclass(frozen=True)
class SavedSigning:
    key: bytes | None
    timestamp: int
    clean: bool


class SigningStore:
    """`signing.key` in the state directory, mode 0600: the key (hex), the timestamp, and whether
    the daemon stopped cleanly. The key is never logged."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def load(self) -> SavedSigning | None:
        try:
            text = self.path.read_text()
        except FileNotFoundError:
            return None
        fields = dict(line.split(None, 1) for line in text.splitlines() if line.strip() and " " in line.strip())
        key_hex = fields.get("key", "none").strip()
        key = None if key_hex == "none" else bytes.fromhex(key_hex)
        if key is not None and len(key) != 32:
            raise ValueError("key is not 32 bytes")
        return SavedSigning(key, int(fields.get("timestamp", "0")), fields.get("clean", "0").strip() == "1")

    def save(self, key: bytes | None, timestamp: int, clean: bool) -> None:
        self.write(self.path, self.text(key, timestamp, clean))

    @staticmethod
    def text(key: bytes | None, timestamp: int, clean: bool) -> str:
        return f"key {key.hex() if key else 'none'}\ntimestamp {timestamp}\nclean {int(clean)}\n"

    @staticmethod
    def write(path: Path, text: str) -> None:
        write_atomic(path, text, mode=0o600)

    @staticmethod
    def restart_floor(saved: SavedSigning) -> int:
        """The highest timestamp the last run may have accepted: the saved one, plus what one save
        interval could add after the last save when the stop was not clean."""
        return saved.timestamp + (0 if saved.clean else int(SAVE_INTERVAL_S * UNITS_PER_S))


class SigningManager:
    """The process's signing: the Signing state, its persistence and the per-channel warnings.

    Key at start: `signing.key` from the configuration if set, else the saved one. A key set by
    SETUP_SIGNING is saved and used until the next start (where a configured key wins again).
    """

    WARN_INTERVAL_S = 10.0

    def __init__(self, config_key: bytes | None, require: bool, store: SigningStore | None, wall_s: float) -> None:
        self.store = store
        self.load_error: str | None = None
        self.load_repair: str | None = None
        saved = None
        if store is not None:
            try:
                saved = store.load()
            except (OSError, ValueError) as exc:
                self.load_error = str(exc)
        if saved is not None and not timestamp_in_bounds(saved.timestamp, wall_s):
            self.load_repair = f"saved timestamp {saved.timestamp} out of bounds: the wall clock replaces it"
            saved = SavedSigning(saved.key, wall_to_units(wall_s), saved.clean)
        floor = SigningStore.restart_floor(saved) if saved else 0
        key = config_key if config_key is not None else (saved.key if saved else None)
        self.signing = Signing(None if key == bytes(32) else key, max(wall_to_units(wall_s), floor), require, floor)
        self._saved_timestamp = -1
        self.save_error: str | None = None  # the last periodic save's failure, until one succeeds
        self._last_warning_s: dict[int, float] = {}

    def apply_key(self, key: bytes, initial_timestamp: int, wall_s: float) -> None:
        self.signing.set_key(key, initial_timestamp, wall_s)
        self.save(clean=False)

    def save(self, clean: bool = False) -> None:
        if self.store is None:
            return
        self.store.save(self.signing.key, self.signing.timestamp, clean)
        self._saved_timestamp = self.signing.timestamp

    def save_if_changed(self) -> None:
        if self._changed():
            self.save(clean=False)

    def _changed(self) -> bool:
        return self.store is not None and self.signing.key is not None and self.signing.timestamp != self._saved_timestamp

    # --- the periodic timestamp save through persist.WriteBehind: snapshot here, write off the loop
    def persist_deadline(self) -> float | None:
        return 0.0 if self._changed() else None

    def take_persist(self, now: float, force: bool = False) -> str | None:
        if not self._changed():
            return None
        self._saved_timestamp = self.signing.timestamp
        return self.store.text(self.signing.key, self.signing.timestamp, False)

    def persist_done(self) -> None:
        self.save_error = None

    def persist_failed(self, error: str) -> None:
        self.save_error = error
        self._saved_timestamp = -1  # written again at the next interval

    def should_warn(self, channel_index: int, now: float) -> bool:
        """At most one warning per WARN_INTERVAL_S per channel."""
        last = self._last_warning_s.get(channel_index)
        if last is not None and now - last < self.WARN_INTERVAL_S:
            return False
        self._last_warning_s[channel_index] = now
        return True
