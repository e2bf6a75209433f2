"""Onboard compass calibration (ArduPilot's AP_Compass calibration over MAVLink), pure.

Commands (ArduPilot's AP_Compass::handle_mag_cal_command):
- DO_START_MAG_CAL: param1 compass mask (0: every compass in use), param2 retry, param3 autosave,
  param4 delay (s), param5 auto-reboot. Armed: FAILED ("Disarm to allow compass calibration");
  a mask outside 0..255 or that selects no compass: FAILED; else ACCEPTED and every selected
  compass runs. A start while one runs restarts it.
- DO_ACCEPT_MAG_CAL: param1 mask (0: all). A finished (successful) compass is saved; one still
  running makes it FAILED; compasses never started are skipped, so with nothing to accept it
  is ACCEPTED (ArduPilot SITL answers so).
- DO_CANCEL_MAG_CAL: stops every compass; always ACCEPTED (QGroundControl sends it first to
  find out whether onboard calibration exists).

States per compass: WAITING_TO_START (param4 delay) -> RUNNING_STEP_ONE (first third) ->
RUNNING_STEP_TWO -> SUCCESS. MAG_CAL_PROGRESS for each running compass every PROGRESS_S
(attempt 1, completion_pct, completion_mask filling bit by bit, direction 0 as ArduPilot sends
it); at the end MAG_CAL_REPORT with the offsets, diagonals and off-diagonals found,
`REPORT_REPEATS` times a second apart (a lost report would leave QGroundControl waiting).
With autosave the result is saved at once (autosaved 1); else it waits for DO_ACCEPT_MAG_CAL.
With auto-reboot (param5) the vehicle reboots once every compass is saved and reported
(`reboot_due`, acted on by the owner), as ArduPilot does after an autosaved calibration.

The simulated vehicle cannot be rotated by the user, so a calibration takes MAG_CAL_S of time
instead of rotations. What it finds is the simulated magnetometer's error, as on ArduPilot SITL:
SIM_MAGn_OFS_* (offsets), SIM_MAGn_DIA_* / _ODI_* (soft iron; DIA 0 means 1), where those
parameters exist, else (5, 13, -18) mGauss, SITL's defaults. Results go into ArduPilot's names:
COMPASS_OFS_X (compass 1), COMPASS_OFS2_X, COMPASS_OFS3_X, likewise DIA/ODI. Which compasses
exist: COMPASS_DEV_ID, _DEV_ID2, _DEV_ID3 non-zero with COMPASS_USE, _USE2, _USE3 set (the rule
QGroundControl uses to build its mask), or compass 1 alone when the parameter set has no
device ids.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.wire.msgids import ACCEPTED, FAILED

MAG_CAL_S = 4.0
PROGRESS_S = 0.5
REPORT_REPEATS = 3
FITNESS = 1.8  # mGauss RMS residual of a noise-free simulated sphere fit (below COMPASS_CAL_FIT)
SITL_OFFSETS = (5.0, 13.0, -18.0)
MAX_COMPASSES = 3


def _suffix(index: int) -> str:
    return "" if index == 0 else str(index + 1)


def compass_params(index: int, kind: str) -> tuple[str, str, str]:
    """COMPASS_OFS_X.. for compass 0, COMPASS_OFS2_X.. for compass 1 (kind OFS, DIA or ODI)."""
    return tuple(f"COMPASS_{kind}{_suffix(index)}_{axis}" for axis in "XYZ")


@dataclass
class CompassRun:
    index: int
    started_s: float  # after the delay
    status: int = M.MAG_CAL_WAITING_TO_START
    result: tuple | None = None  # (offsets, diagonals, offdiagonals)
    saved: bool = False
    reports_left: int = REPORT_REPEATS
    next_send_s: float = 0.0


@dataclass
class MagCal:
    """The calibration of every selected compass; `params` is the node's ParamStore."""

    params: object
    runs: dict[int, CompassRun] = field(default_factory=dict)
    autosave: bool = False
    autoreboot: bool = False
    saved_any: bool = False
    reboot_due: bool = False  # autoreboot: every compass saved and reported; the owner reboots

    # --- which compasses ---------------------------------------------------------------------
    def compasses(self) -> list[int]:
        p = self.params
        if "COMPASS_OFS_X" not in p:
            return []
        if "COMPASS_DEV_ID" not in p:
            return [0]
        out = []
        for i in range(MAX_COMPASSES):
            dev, use = f"COMPASS_DEV_ID{_suffix(i)}", f"COMPASS_USE{_suffix(i)}"
            if dev in p and p.get(dev) > 0 and (use not in p or p.get(use)) and compass_params(i, "OFS")[0] in p:
                out.append(i)
        return out

    # --- commands ----------------------------------------------------------------------------
    def start(self, mask: float, autosave: bool, delay_s: float, now: float, autoreboot: bool = False) -> int:
        if not 0 <= mask <= 255:
            return FAILED
        selected = [i for i in self.compasses() if int(mask) == 0 or int(mask) & (1 << i)]
        if not selected:
            return FAILED
        delay_s = max(0.0, min(delay_s, 60.0)) if math.isfinite(delay_s) else 0.0
        self.autosave = autosave
        self.autoreboot = autoreboot
        self.runs = {i: CompassRun(i, now + delay_s, next_send_s=now) for i in selected}
        return ACCEPTED

    def accept(self, mask: float) -> int:
        if not 0 <= mask <= 255:
            return FAILED
        bits = int(mask) or 0xFF
        ok = True
        for i, run in list(self.runs.items()):
            if not bits & (1 << i):
                continue
            if run.status != M.MAG_CAL_SUCCESS:
                ok = False
                continue
            if not run.saved:
                self._save(run)
            del self.runs[i]
        return ACCEPTED if ok else FAILED

    def cancel(self) -> int:
        self.runs = {}
        return ACCEPTED

    def running(self) -> bool:
        return any(r.status not in (M.MAG_CAL_SUCCESS, M.MAG_CAL_FAILED) for r in self.runs.values())

    # --- time --------------------------------------------------------------------------------
    def _mask(self) -> int:
        mask = 0
        for i in self.runs:
            mask |= 1 << i
        return mask

    def simulated_error(self, index: int) -> tuple:
        p = self.params
        n = index + 1

        def triple(kind: str, default: tuple) -> tuple:
            names = [f"SIM_MAG{n}_{kind}_{axis}" for axis in "XYZ"]
            if all(name in p for name in names):
                return tuple(float(p.get(name)) for name in names)
            return default

        offsets = triple("OFS", SITL_OFFSETS)
        diag = tuple(d or 1.0 for d in triple("DIA", (1.0, 1.0, 1.0)))
        offdiag = triple("ODI", (0.0, 0.0, 0.0))
        return offsets, diag, offdiag

    def _save(self, run: CompassRun) -> None:
        offsets, diag, offdiag = run.result
        for kind, values in (("OFS", offsets), ("DIA", diag), ("ODI", offdiag)):
            for name, value in zip(compass_params(run.index, kind), values):
                if name in self.params:
                    self.params.set(name, value, force=True)
        run.saved = True
        self.saved_any = True

    def messages(self, now: float) -> list:
        """MAG_CAL_PROGRESS / MAG_CAL_REPORT due now (for every ground station)."""
        out = []
        mask = self._mask()
        for run in list(self.runs.values()):
            if now < run.next_send_s:
                continue
            if run.status in (M.MAG_CAL_SUCCESS, M.MAG_CAL_FAILED):
                if run.reports_left <= 0:
                    continue
                run.reports_left -= 1
                run.next_send_s = now + 1.0
                out.append(self._report(run, mask))
                continue
            elapsed = now - run.started_s
            if elapsed < 0:
                run.status = M.MAG_CAL_WAITING_TO_START
                pct = 0
            elif elapsed >= MAG_CAL_S:
                run.status = M.MAG_CAL_SUCCESS
                run.result = self.simulated_error(run.index)
                if self.autosave:
                    self._save(run)
                run.reports_left -= 1
                run.next_send_s = now + 1.0
                out.append(self._report(run, mask))
                continue
            else:
                pct = int(100 * elapsed / MAG_CAL_S)
                run.status = M.MAG_CAL_RUNNING_STEP_ONE if pct < 33 else M.MAG_CAL_RUNNING_STEP_TWO
            run.next_send_s = now + PROGRESS_S
            sections = pct * 80 // 100  # 80 sphere sections, filled as the fit progresses
            completion_mask = [0] * 10
            for bit in range(sections):
                completion_mask[bit // 8] |= 1 << (bit % 8)
            out.append(M.MAVLink_mag_cal_progress_message(
                run.index, mask, run.status, 1, pct, completion_mask, 0.0, 0.0, 0.0))
        if self.runs and not any(r.reports_left > 0 or not r.saved for r in self.runs.values()):
            self.runs = {}  # autosaved and reported: nothing left to accept
            self.reboot_due = self.autoreboot
        return out

    def _report(self, run: CompassRun, mask: int):
        offsets, diag, offdiag = run.result
        return M.MAVLink_mag_cal_report_message(
            run.index, mask, run.status, int(run.saved), FITNESS, *offsets, *diag, *offdiag,
            1.0, M.MAV_SENSOR_ROTATION_NONE, M.MAV_SENSOR_ROTATION_NONE, 1.0)

    def next_deadline(self) -> float | None:
        due = [r.next_send_s for r in self.runs.values()
               if r.reports_left > 0 or r.status not in (M.MAG_CAL_SUCCESS, M.MAG_CAL_FAILED)]
        return min(due) if due else None
