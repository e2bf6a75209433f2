"""Ground maintenance commands: calibration, storage, reboot, pre-arm checks, compass calibration.

- PREFLIGHT_CALIBRATION: gyro (param1 1), barometer (param3 1), level (param5 2), simple
  accelerometer (param5 4), airspeed (param6 2) run in the long-running slot: IN_PROGRESS at
  once and every second, ACCEPTED when done, with ArduPilot's STATUSTEXT. Full accelerometer,
  compass-motor, RC and temperature calibrations are interactive on ArduPilot: UNSUPPORTED.
  Armed: TEMPORARILY_REJECTED.
- STORAGE_FORMAT (param1 1 and param2 1, else UNSUPPORTED): long-running; empties the FTP root
  (the vehicle's "SD card"); parameters and plans, which live beside it, stay.
- PREFLIGHT_STORAGE: param1 0 read and 1 write are ACCEPTED (parameters are saved on every
  change); 2 resets every writable parameter to its default and saves.
- PREFLIGHT_REBOOT_SHUTDOWN param1 1 or 3: refused while armed (FAILED); else the simulated
  vehicle reboots (disarmed, initial mode, mission restarted, failsafes and outputs reset,
  STAT_BOOTCNT + 1, banner). Parameters marked "reboot required" take effect at the next start
  of gcsd. param1 0: nothing; 2 (shutdown) and the debug magics: UNSUPPORTED.
- RUN_PREARM_CHECKS: each failure as "PreArm: ..." STATUSTEXT; ACCEPTED (TEMPORARILY_REJECTED
  armed).
- DO_START_MAG_CAL, DO_ACCEPT_MAG_CAL, DO_CANCEL_MAG_CAL: a simulated compass calibration:
  MAG_CAL_PROGRESS every second for MAG_CAL_S, then MAG_CAL_REPORT with the offsets found;
  saved into COMPASS_OFS_X/Y/Z when accepted (or at once with autosave, param3 1).
  FIXED_MAG_CAL_YAW saves them at once (disarmed).
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from . import Service
from .commands import CommandRequest
from .longrunning import LongRunning

log = structlog.get_logger("gcsd.maintenance")

ACCEPTED, DENIED, FAILED, UNSUPPORTED, LATER = (
    M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_DENIED, M.MAV_RESULT_FAILED, M.MAV_RESULT_UNSUPPORTED,
    M.MAV_RESULT_TEMPORARILY_REJECTED)
CALIBRATION_S = 2.0
FORMAT_S = 1.0
MAG_CAL_S = 4.0
SIMULATED_OFFSETS = (4.0, -9.0, 15.0)  # what a compass calibration finds on the simulated vehicle


class MaintenanceService(Service):
    capabilities = M.MAV_PROTOCOL_CAPABILITY_COMPASS_CALIBRATION  # DO_START_MAG_CAL and its reports

    def __init__(self, node, ftp_root: Path | None = None) -> None:
        self.node = node
        self.ftp_root = ftp_root
        self.slot = LongRunning()
        self.mag_cal: dict | None = None

    def commands(self):
        return {
            M.MAV_CMD_PREFLIGHT_CALIBRATION: self.calibration, M.MAV_CMD_STORAGE_FORMAT: self.storage_format,
            M.MAV_CMD_PREFLIGHT_STORAGE: self.storage, M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: self.reboot,
            M.MAV_CMD_RUN_PREARM_CHECKS: self.run_prearm_checks, M.MAV_CMD_DO_START_MAG_CAL: self.start_mag_cal,
            M.MAV_CMD_DO_ACCEPT_MAG_CAL: self.accept_mag_cal, M.MAV_CMD_DO_CANCEL_MAG_CAL: self.cancel_mag_cal,
            M.MAV_CMD_FIXED_MAG_CAL_YAW: self.fixed_mag_cal_yaw,
        }

    # --- calibration -------------------------------------------------------------------------
    def calibration(self, req: CommandRequest) -> int:
        if self.node.state.armed:
            return LATER
        p = [round(v) if math.isfinite(v) else 0 for v in (req.param1, req.param2, req.param3, req.param4, req.x, req.y)]
        texts = []
        if p[0] == 1:
            texts.append("Gyro calibration complete")
        if p[2] == 1:
            texts.append("Barometer calibration complete")
        if p[4] == 2:
            texts.append("Trim OK: roll=0.00 pitch=0.00")
        if p[4] == 4:
            texts.append("Accelerometer calibration complete")
        if p[5] == 2:
            texts.append("Airspeed 1 calibrated")
        interactive = p[0] == 3 or p[1] == 1 or p[3] == 1 or p[4] == 1 or p[5] == 1
        if not texts or interactive:
            return UNSUPPORTED
        self.node.send_text(M.MAV_SEVERITY_INFO, "Calibrating sensors")

        def finish() -> int:
            for text in texts:
                self.node.send_text(M.MAV_SEVERITY_INFO, text)
            return ACCEPTED

        return self._long(req, CALIBRATION_S, finish)

    def storage_format(self, req: CommandRequest) -> int:
        if req.param1 != 1 or req.param2 != 1:
            return UNSUPPORTED
        if self.node.state.armed:
            return LATER
        return self._long(req, FORMAT_S, self._format)

    def _format(self) -> int:
        root = self.ftp_root
        if root is None or not root.is_dir():
            return FAILED
        try:
            for child in root.iterdir():
                if child.is_dir() and not child.is_symlink():
                    shutil.rmtree(child)
                else:
                    child.unlink()
        except OSError as exc:
            log.error("storage_format_failed", root=str(root), error=str(exc))
            return FAILED
        self.node.send_text(M.MAV_SEVERITY_INFO, "Storage formatted")
        return ACCEPTED

    def _long(self, req: CommandRequest, duration_s: float, finish) -> int:
        result = self.slot.start(req.command, req.inc.sender, req.inc.channel, req.inc.now, duration_s, finish)
        self.node.wake(req.inc.channel)
        return result

    # --- storage, reboot, checks -------------------------------------------------------------
    def storage(self, req: CommandRequest) -> int:
        if req.param1 in (0, 1):
            return ACCEPTED
        if req.param1 != 2:
            return UNSUPPORTED
        store = self.node.params
        for entry in list(store.entries()):
            if not store.definition(entry.name).read_only:
                store.set(entry.name, entry.default, force=True)
        try:
            self.node.param_service.save()
        except OSError:
            return FAILED
        self.node.send_text(M.MAV_SEVERITY_WARNING, "All parameters reset to defaults")
        return ACCEPTED

    def reboot(self, req: CommandRequest) -> int:
        what = round(req.param1) if math.isfinite(req.param1) else -1
        if what == 0:
            return ACCEPTED
        if what not in (1, 3):
            return UNSUPPORTED
        if self.node.state.armed:
            return FAILED
        self.node.send_text(M.MAV_SEVERITY_INFO, "Rebooting")
        self.node.sim.reboot()
        store = self.node.params
        store.set("STAT_BOOTCNT", store.get("STAT_BOOTCNT") + 1, force=True)
        try:
            self.node.param_service.save()
        except OSError as exc:
            log.error("params_save_failed", error=str(exc))
        self.node.send_banner()
        return ACCEPTED

    def run_prearm_checks(self, req: CommandRequest) -> int:
        if self.node.state.armed:
            return LATER
        for text in self.node.prearm_failures():
            self.node.send_text(M.MAV_SEVERITY_CRITICAL, f"PreArm: {text}")
        return ACCEPTED

    # --- compass calibration -----------------------------------------------------------------
    def start_mag_cal(self, req: CommandRequest) -> int:
        if self.node.state.armed:
            return LATER
        if "COMPASS_OFS_X" not in self.node.params:
            return UNSUPPORTED
        self.mag_cal = {"started": req.inc.now, "autosave": req.param3 >= 1, "next": req.inc.now,
                        "done": False, "channel": req.inc.channel}
        self.node.wake(req.inc.channel)
        return ACCEPTED

    def accept_mag_cal(self, req: CommandRequest) -> int:
        cal = self.mag_cal
        if cal is None or not cal["done"]:
            return FAILED
        self._save_offsets()
        self.mag_cal = None
        return ACCEPTED

    def cancel_mag_cal(self, req: CommandRequest) -> int:
        self.mag_cal = None
        return ACCEPTED

    def fixed_mag_cal_yaw(self, req: CommandRequest) -> int:
        """FIXED_MAG_CAL_YAW: calibrate from a known heading at once (the vehicle must be still)."""
        if self.node.state.armed or "COMPASS_OFS_X" not in self.node.params:
            return FAILED
        self._save_offsets()
        self.node.send_text(M.MAV_SEVERITY_INFO, f"Mag cal from yaw {req.param1:.0f}: offsets saved")
        return ACCEPTED

    def _save_offsets(self) -> None:
        for axis, value in zip("XYZ", SIMULATED_OFFSETS):
            self.node.params.set(f"COMPASS_OFS_{axis}", value, force=True)
        try:
            self.node.param_service.save()
        except OSError as exc:
            log.error("params_save_failed", error=str(exc))

    def _mag_cal_messages(self, now: float) -> list:
        cal = self.mag_cal
        if cal is None or cal["done"] or now < cal["next"]:
            return []
        pct = min(100, int(100 * (now - cal["started"]) / MAG_CAL_S))
        if pct < 100:
            cal["next"] = now + 1.0
            return [M.MAVLink_mag_cal_progress_message(0, 1, 1, M.MAG_CAL_RUNNING_STEP_TWO, 1, pct, [0] * 10,
                                                       0.0, 0.0, 1.0)]
        cal["done"] = True
        if cal["autosave"]:
            self._save_offsets()
            self.mag_cal = None
        x, y, z = SIMULATED_OFFSETS
        return [M.MAVLink_mag_cal_report_message(0, 1, 1, M.MAG_CAL_SUCCESS, int(cal["autosave"]), 4.5, x, y, z,
                                                 1.0, 1.0, 1.0, 0.0, 0.0, 0.0)]

    # --- the send pass -----------------------------------------------------------------------
    def pending(self, channel, now: float, send) -> float | None:
        for ack in self.slot.due(channel, now):
            send(ack)
        cal = self.mag_cal
        if cal is not None and cal["channel"] is channel:
            for msg in self._mag_cal_messages(now):
                send(msg)
        deadlines = [d for d in (self.slot.next_deadline(),
                                 None if self.mag_cal is None or self.mag_cal["done"] else self.mag_cal["next"])
                     if d is not None]
        return min(deadlines) if deadlines else None
