"""The parameter protocol (REFERENCE.md section 6) over a ParamStore, with persistence.

- PARAM_REQUEST_LIST starts (or restarts) a list download for the requester, keyed by
  (sysid, compid, channel): two ground stations downloading at once each get every index. The
  banner STATUSTEXTs go first. Values are then streamed by `pending()` in the channel's send
  pass: as many per pass as the byte budget allows (at most BURST per pass, then the pass
  yields), so a 57600-baud radio is never flooded and loopback gets 1000 values in a blink.
  While a list streams, the link's telemetry is slowed x4.
- PARAM_REQUEST_READ by index (index >= 0) or by name (index -1) is answered at once on the
  requesting link; an unknown name or index gets no reply (as ArduPilot).
- PARAM_SET: unknown names, NaN and infinity are ignored. Read-only parameters and values
  outside the documented range are refused with a STATUSTEXT and the old value sent back to
  the requester. A change is saved and confirmed with PARAM_VALUE on every active, non-private
  channel. (PARAM_VALUE carries the parameter's real index; ArduPilot sends 65535 there.)
- Persistence: `mav.parm` in the vehicle's state directory holds the values that differ from
  their defaults, written atomically after every change. At start: defaults, then
  `params_file`, then the saved file. Unreadable lines are logged with their line numbers and
  those parameters keep their defaults; a damaged saved file is kept as `mav.parm.bad` before
  it is ever overwritten.
"""

from __future__ import annotations

import time
from pathlib import Path

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from ..atomic import write_atomic
from ..params import ParamEntry, ParamStore, SetResult, as_float
from ..params.parmfile import format_parm, read_parm
from . import Incoming, Service

log = structlog.get_logger("gcsd.params")

BURST = 100  # PARAM_VALUEs per send pass on a link with room to spare
PARAM_VALUE_BYTES = 37  # MAVLink2 PARAM_VALUE: 12 bytes of framing + 25 of payload


class ParamService(Service):
    capabilities = M.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT

    def __init__(self, node, store: ParamStore, save_path: Path | None) -> None:
        self.node = node
        self.store = store
        self.save_path = save_path
        self._lists: dict[tuple[int, int, int], int] = {}  # requester -> next index
        self._started_s = time.monotonic()
        self._runtime_base = 0

    # --- loading and saving ----------------------------------------------------------------
    def load(self, params_file: Path | None) -> None:
        if params_file is not None:
            self._apply_file(params_file, "params_file")
        if self.save_path is not None and self.save_path.exists():
            if self._apply_file(self.save_path, "saved"):
                bad = self.save_path.with_name(self.save_path.name + ".bad")
                bad.write_bytes(self.save_path.read_bytes())
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

    def save(self) -> None:
        if self.save_path is None:
            return
        runtime = self._runtime_base + int(time.monotonic() - self._started_s)
        self.store.set("STAT_RUNTIME", runtime, force=True)
        write_atomic(self.save_path, format_parm(self.store.changed_from_default()))

    def set_from_file(self, name: str, value: float, save: bool = True) -> bool:
        """Set a parameter uploaded as a file (FTP param.pck): no echo, read-only refused."""
        result = self.store.set(name, value)
        if result is SetResult.CHANGED and save:
            self.save()
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
        self.node.send_banner()
        self.node.link(inc.channel).set_slow("params", True)
        self.node.wake(inc.channel)

    def handle_PARAM_REQUEST_READ(self, inc: Incoming) -> None:
        m = inc.msg
        if m.param_index >= 0:
            entry = self.store.entry(m.param_index)
        else:
            entry = self.store.entry_by_name(_name(m.param_id))
        if entry is not None:
            self.node.reply(inc.channel, self._value_msg(entry))

    def handle_PARAM_SET(self, inc: Incoming) -> None:
        name = _name(inc.msg.param_id)
        result = self.store.set(name, inc.msg.param_value)
        if result in (SetResult.UNKNOWN, SetResult.INVALID):
            return
        entry = self.store.entry_by_name(name)
        if result in (SetResult.READ_ONLY, SetResult.OUT_OF_RANGE):
            d = self.store.definition(name)
            if result is SetResult.READ_ONLY:
                text = f"Param write denied ({name})"
            else:
                text = f"Param {name} out of range ({d.min:g}..{d.max:g})"
            self.node.send_text(M.MAV_SEVERITY_WARNING, text, channels={inc.channel.index})
            self.node.reply(inc.channel, self._value_msg(entry))
            return
        if result is SetResult.CHANGED:
            try:
                self.save()
            except OSError as exc:
                log.error("params_save_failed", path=str(self.save_path), error=str(exc))
                self.node.send_text(M.MAV_SEVERITY_ERROR, f"Param save failed ({name})")
            if self.store.definition(name).reboot:
                self.node.send_text(M.MAV_SEVERITY_INFO, f"{name} takes effect at the next start")
        msg = self._value_msg(entry)
        for channel in self.node.channels:
            if channel.peers and not channel.policy.private:
                self.node.reply(channel, msg)

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
            self.node.link(channel).set_slow("params", False)
            return None
        return now


def _name(raw) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", "replace")
    return raw.split("\0", 1)[0]
