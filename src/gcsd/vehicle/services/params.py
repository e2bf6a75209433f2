"""The parameter protocol (REFERENCE.md section 6) over a ParamStore, with persistence.

- PARAM_REQUEST_LIST starts (or restarts) a list download for the requester, keyed by
  (sysid, compid, channel): two ground stations downloading at once each get every index. The
  banner STATUSTEXTs go first. Values are then streamed by `pending()` in the channel's send
  pass: as many per pass as the byte budget allows and at most BURST per pass, so a 57600-baud
  radio is never flooded. A datagram link (UDP, MQTT) has no flow control: there one full burst
  goes per BURST_INTERVAL_S (3 000 values a second: ArduCopter's 1 000 in 0.33 s), so a ground
  station reading its socket with the kernel's default buffer keeps up: each PARAM_VALUE is one
  datagram, a default 208 KiB receive buffer holds only ~270 of them, and a busy pymavlink
  client lost 700 of 1 000 sent at full speed. ArduPilot paces the same way: queued_param_send
  sends at most 5 values per loop when the link has no flow control (~2 000 a second; SITL
  served 1 354 in 0.70 s). A stream link (TCP, serial) goes as fast as its budget allows:
  the services' turn comes before the streams, within its share of the budget while they are
  due (scheduler.ServiceShare: 1 000 values in ~55 s at 9 600 baud with the default streams).
  While a list streams, the link's telemetry is slowed x4.
- PARAM_REQUEST_READ by index (index >= 0) or by name (index -1) is answered at once on the
  requesting link; an unknown name or index gets no reply (as ArduPilot).
- PARAM_SET: unknown names, NaN and infinity are ignored. Read-only parameters are refused
  with a STATUSTEXT and the old value sent back to the requester. Any other finite value is
  stored, also outside the documented range, as ArduPilot's GCS_Param.cpp does (the range is
  advice for ground stations; what acts on a parameter clamps it, ParamStore.clamped, and the
  pre-arm checks report the dangerous ones). A value `vet` refuses (the composition root's
  check that SYSID_THISMAV stays distinct across a swarm, params/sysids.py) is answered as a
  read-only parameter is: its reason as STATUSTEXT and the old value back. A change is saved and
  confirmed with PARAM_VALUE on every active, non-private channel. (PARAM_VALUE carries the parameter's real index; ArduPilot sends 65535 there.)
- Persistence, write-behind: `mav.parm` in the vehicle's state directory holds the values that
  differ from their defaults. A change only marks the service dirty (`mark_dirty`, and the
  `on_dirty` hook tells the I/O adapter, gcsd.persist.WriteBehind). The file is due at
  `persist_deadline()`: at once after a quiet second, else one PERSIST_INTERVAL_S after the
  previous write, so a burst of 1 000 PARAM_SETs costs two writes (the first change, then the
  rest), and a single change is on disk within milliseconds. `take_persist(now)` renders the
  text on the caller's thread (a consistent snapshot) and the adapter writes it atomically on
  a worker thread; a clean stop flushes what is left. A failed write is retried a second
  later and reported once by STATUSTEXT. REAL32 values are written so they read back bit-exact
  (parmfile.format_real32). No clock is read here: `now` always comes from the caller.
- At start: defaults, then `params_file`, then the saved file. A problem in `params_file` (a
  bad line, an unknown name, a value out of its type's range, NaN) is a bad
  configuration: `load` raises ConfigError with a ``FILE:LINE: NAME: what`` line for each, and
  the daemon does not start (exit 2) rather than run with half of an operator's settings. The
  daemon's own saved file is state, not configuration: unreadable lines there are logged with
  their line numbers, those parameters keep their defaults, and the damaged file is kept as
  `mav.parm.bad` before it is ever overwritten.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.config import ConfigError
from gcsd.config.schema import DATAGRAM_TYPES
from gcsd.vehicle.params import ParamEntry, ParamStore, SetResult, as_float, to_type
from gcsd.vehicle.params.parmfile import format_parm, read_parm, read_parm_lines
from gcsd.vehicle.params.store import REAL32, TYPE_RANGE, fits_real32
from gcsd.vehicle.services import Incoming, Service

log = structlog.get_logger("gcsd.vehicle.params")

BURST = 30  # PARAM_VALUEs per send pass on a link with room to spare
BURST_INTERVAL_S = 0.01  # ...and, on a datagram link, at most one full burst per 10 ms
PARAM_VALUE_BYTES = 37  # MAVLink2 PARAM_VALUE: 12 bytes of framing + 25 of payload
PERSIST_INTERVAL_S = 1.0  # at most one write of mav.parm per second


class ParamService(Service):
    capabilities = M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT

    def __init__(self, ctx, store: ParamStore, save_path: Path | None, now: float = 0.0) -> None:
        self.ctx = ctx
        self.store = store
        self.save_path = save_path
        self._lists: dict[tuple[int, int, int], int] = {}  # requester -> next index
        self._started_s = now
        self._runtime_base = 0
        self._dirty = False
        self._last_write_s = -math.inf
        self._failing = False  # the last write failed (reported once until one succeeds)
        self.on_dirty: Callable[[], None] = lambda: None  # the I/O adapter's wake-up (persist.py)
        self.vet: Callable[[str, float], str | None] = lambda name, value: None  # why a write is refused

    # --- loading -----------------------------------------------------------------------------
    def load(self, params_file: Path | None) -> None:
        if params_file is not None:
            problems = params_file_problems(self.store, params_file)
            if problems:
                raise ConfigError(problems)
            self._apply_file(params_file, "params_file")
        saved = self.save_path
        if saved is not None and saved.exists() and self._apply_file(saved, "saved"):
            bad = saved.with_name(saved.name + ".bad")
            bad.write_bytes(saved.read_bytes())
            log.warning("params_saved_file_kept", path=str(bad))
        self._runtime_base = int(self.store.get("STAT_RUNTIME"))

    def _apply_file(self, path: Path, source: str) -> int:
        """Apply a .parm file; returns the number of problems found (each one logged)."""
        try:
            values, problems = read_parm(path)
        except OSError as exc:
            log.error("params_file_unreadable", path=str(path), source=source, error=str(exc))
            return 1
        for p in problems:
            log.warning("params_file_line_invalid", path=str(path), line=p.line, text=p.text, reason=p.reason)
        count = len(problems)
        for name, value in values.items():
            result = self.store.set(name, value, force=True)
            if result in (SetResult.UNKNOWN, SetResult.OUT_OF_RANGE, SetResult.INVALID):
                log.warning("params_file_value_ignored", path=str(path), name=name, value=value, reason=result.value)
                count += 1
        log.info("params_loaded", path=str(path), source=source, values=len(values), problems=count)
        return count

    # --- write-behind persistence (the pure half; persist.WriteBehind does the I/O) ----------
    def mark_dirty(self) -> None:
        """Values changed: the file is due at `persist_deadline()`."""
        if self.save_path is None:
            return
        self._dirty = True
        self.on_dirty()

    save = mark_dirty  # what services call after changing parameters themselves (never raises)

    def persist_deadline(self) -> float | None:
        """When the file should next be written (None: nothing to write)."""
        return self._last_write_s + PERSIST_INTERVAL_S if self._dirty else None

    def take_persist(self, now: float, force: bool = False) -> str | None:
        """The file's new text if a write is due at `now` (or `force`: a clean stop), else None.
        The service is clean afterwards; `persist_failed` makes it dirty again."""
        deadline = self.persist_deadline()
        if deadline is None or (now < deadline and not force):
            return None
        runtime = self._runtime_base + int(max(0.0, now - self._started_s))
        self.store.set("STAT_RUNTIME", runtime, force=True)
        self._dirty = False
        self._last_write_s = now
        return format_parm(self.store.changed_from_default())

    def persist_done(self) -> None:
        if self._failing:
            log.info("params_save_recovered", path=str(self.save_path))
        self._failing = False

    def persist_failed(self, error: str) -> None:
        """The write failed: try again a PERSIST_INTERVAL_S later; log it and tell the ground
        stations once per run of failures (a full disk must not log every second)."""
        if not self._failing:
            self._failing = True
            log.error("params_save_failed", path=str(self.save_path), error=error)
            self.ctx.text(M.MAV_SEVERITY_ERROR, "Param save failed")
        self.mark_dirty()

    def _refusal(self, name: str, value: float) -> str | None:
        if name not in self.store or not math.isfinite(value):
            return None
        return self.vet(name, to_type(self.store.definition(name).ptype, value))

    def set_from_file(self, name: str, value: float, save: bool = True) -> bool:
        """Set a parameter uploaded as a file (FTP param.pck): no echo, read-only and vetoed refused."""
        if self._refusal(name, value) is not None:
            return False
        result = self.store.set(name, value)
        if result is SetResult.CHANGED and save:
            self.mark_dirty()
        return result in (SetResult.CHANGED, SetResult.UNCHANGED)

    # --- messages --------------------------------------------------------------------------
    def _value_msg(self, entry: ParamEntry, index: int | None = None):
        return M.MAVLink_param_value_message(
            entry.name.encode(), as_float(entry.value), entry.ptype, len(self.store),
            entry.index if index is None else index,
        )

    def handle_PARAM_REQUEST_LIST(self, inc: Incoming) -> None:
        key = (inc.frame.sysid, inc.frame.compid, inc.channel.index)
        self._lists[key] = 0
        self.ctx.banner()
        self.ctx.link(inc.channel).set_slow("params", True)
        self.ctx.wake(inc.channel)

    def handle_PARAM_REQUEST_READ(self, inc: Incoming) -> None:
        m = inc.msg
        if m.param_index >= 0:
            entry = self.store.entry(m.param_index)
        else:
            entry = self.store.entry_by_name(_name(m.param_id))
        if entry is not None:
            self.ctx.reply(inc.channel, self._value_msg(entry))

    def handle_PARAM_SET(self, inc: Incoming) -> None:
        name = _name(inc.msg.param_id)
        refused = self._refusal(name, inc.msg.param_value)
        result = SetResult.READ_ONLY if refused else self.store.set(name, inc.msg.param_value)
        if result in (SetResult.UNKNOWN, SetResult.INVALID):
            return
        entry = self.store.entry_by_name(name)
        if result is SetResult.READ_ONLY:
            why = refused or f"Param write denied ({name})"
            self.ctx.text(M.MAV_SEVERITY_WARNING, why, channels={inc.channel.index})
            self.ctx.reply(inc.channel, self._value_msg(entry))
            return
        if result is SetResult.CHANGED:
            self.mark_dirty()
            if self.store.definition(name).reboot:
                self.ctx.text(M.MAV_SEVERITY_INFO, f"{name} takes effect at the next start")
        msg = self._value_msg(entry)
        for channel in self.ctx.channels:
            if channel.peers and not channel.policy.private:
                self.ctx.reply(channel, msg)

    # --- the paced list download -----------------------------------------------------------
    def pending(self, channel, now: float, send) -> float | None:
        """Stream list values on one channel; returns when to come back (None: nothing to do)."""
        keys = [k for k in self._lists if k[2] == channel.index]
        if not keys:
            return None
        sent = 0
        for key in keys:
            index = self._lists[key]
            while index < len(self.store) and sent < BURST:
                if not channel.has_room(PARAM_VALUE_BYTES) or not send(self._value_msg(self.store.entry(index))):
                    self._lists[key] = index
                    return now + max(channel.budget_wait_s(PARAM_VALUE_BYTES), 0.001)
                index += 1
                sent += 1
            self._lists[key] = index
            if index >= len(self.store):
                del self._lists[key]
        if not any(k[2] == channel.index for k in self._lists):
            self.ctx.link(channel).set_slow("params", False)
            return None
        paced = sent >= BURST and channel.config.type in DATAGRAM_TYPES
        return now + BURST_INTERVAL_S if paced else now


def params_file_problems(store: ParamStore, path: Path) -> list[str]:
    """Every problem of a configured params_file, as ``FILE:LINE: NAME: what`` lines."""
    try:
        lines, bad = read_parm_lines(path)
    except OSError as exc:
        return [f"{path}: cannot read: {exc.strerror or exc}"]
    problems = [(p.line, f"{path}:{p.line}: {p.reason}" + (f": {p.text!r}" if p.text else "")) for p in bad]
    for p in lines:
        why = _file_value_problem(store, p.name, p.value)
        if why:
            problems.append((p.line, f"{path}:{p.line}: {p.name}: {why}"))
    return [text for _, text in sorted(problems)]


def _file_value_problem(store: ParamStore, name: str, value: float) -> str | None:
    if name not in store:
        return "no such parameter"
    d = store.definition(name)
    if d.ptype == REAL32 and not fits_real32(value):
        return f"{value:g} is out of range for a REAL32 (a 32-bit float)"
    if d.ptype in TYPE_RANGE and not TYPE_RANGE[d.ptype][0] <= value <= TYPE_RANGE[d.ptype][1]:
        lo, hi = TYPE_RANGE[d.ptype]
        return f"{value:g} is out of range for its type ({lo}..{hi})"
    return None  # outside the documented range is fine: stored, as a PARAM_SET's value is


def _name(raw) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", "replace")
    return raw.split("\0", 1)[0]
