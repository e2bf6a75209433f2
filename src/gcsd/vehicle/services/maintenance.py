"""Ground maintenance commands: calibration, storage, reboot, pre-arm checks, compass calibration.

- PREFLIGHT_CALIBRATION (armed: TEMPORARILY_REJECTED):
  - param5 1: the six-position accelerometer dialogue (`accelcal`): ACCEPTED at once, as
    ArduPilot; the vehicle then asks for each position (COMMAND_LONG ACCELCAL_VEHICLE_POS and
    "Place vehicle ... and press any key." STATUSTEXT); a ground station's COMMAND_ACK or
    ACCELCAL_VEHICLE_POS answers it. All params 0 while it runs cancels it (QGroundControl's
    Cancel): ACCEPTED.
  - gyro (param1 1), barometer (param3 1), level (param5 2), simple accelerometer (param5 4),
    airspeed (param6 2) run in the long-running slot: IN_PROGRESS at once and every second,
    ACCEPTED when done (QGroundControl's Sensors page waits for that ACK), with ArduPilot's
    STATUSTEXT; the result lands where ArduPilot keeps it: INS_GYROFFS_* (the simulated IMU's
    SIM_GYRn_BIAS_*), BARO1_GND_PRESS (the simulated pressure at the current altitude),
    AHRS_TRIM_X/Y (the vehicle's attitude now), INS_ACCOFFS_* / INS_ACCSCAL_* (the simulated
    IMU's offsets, `accelcal.imu_error`; scales 1, trim 0).
  - param4 1 alone: a plane's or rover's trim_radio (VehicleType.radio_trim_sticks): the roll,
    pitch and yaw (steering) RCn_TRIM take the current RC input; ACCEPTED at once. A copter has
    no such calibration (UNSUPPORTED, as ArduCopter).
  - compass-motor (param6 1), temperature (param1 3) and ground pressure (param2 1) need
    hardware that a simulation does not have: UNSUPPORTED.
- ACCELCAL_VEHICLE_POS: ACCEPTED for the position the running dialogue asks for, else FAILED.
- STORAGE_FORMAT (param1 1 and param2 1, else UNSUPPORTED): long-running; empties the FTP root
  (the vehicle's "SD card"); parameters and plans, which live beside it, stay.
- PREFLIGHT_STORAGE: param1 0 read and 1 write are ACCEPTED (parameters are saved on every
  change); 2 resets every writable parameter to its default and saves.
- PREFLIGHT_REBOOT_SHUTDOWN param1 1 or 3: refused while armed (FAILED); else the simulated
  vehicle reboots (disarmed, initial mode, mission restarted, failsafes and outputs reset,
  STAT_BOOTCNT + 1, banner). Parameters marked "reboot required" take effect at the next start
  of gcsd. param1 0: nothing; 2 (shutdown) and the debug magics: UNSUPPORTED.
- RUN_PREARM_CHECKS: each failure as "PreArm: ..." STATUSTEXT; ACCEPTED (TEMPORARILY_REJECTED
  armed). Unasked, while disarmed, the failures are shown as ArduPilot shows them
  (`vehicles.prearm.PrearmDisplay`: every 30 s, or 4 s after they change).
- DO_START_MAG_CAL, DO_ACCEPT_MAG_CAL, DO_CANCEL_MAG_CAL: a simulated onboard compass
  calibration (`magcal`): MAG_CAL_PROGRESS and MAG_CAL_REPORT to every ground station,
  results into COMPASS_OFS*/DIA*/ODI* when accepted, or at once with autosave (param3 1);
  with auto-reboot (param5 1) the vehicle then reboots.
  FIXED_MAG_CAL_YAW saves the offsets at once (disarmed).
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.services import Incoming, Service
from gcsd.vehicle.services.accelcal import FAILURE, AccelCal, imu_error
from gcsd.vehicle.services.commands import CommandRequest
from gcsd.vehicle.services.longrunning import LongRunning
from gcsd.vehicle.services.magcal import MagCal, compass_params
from gcsd.vehicle.types import rc
from gcsd.vehicle.types.prearm import PrearmDisplay
from gcsd.wire.msgids import ACCEPTED, FAILED, UNSUPPORTED
from gcsd.wire.msgids import TEMPORARILY_REJECTED as LATER

log = structlog.get_logger("gcsd.maintenance")

CALIBRATION_S = 2.0
MAG_OUTBOX = 32
FORMAT_S = 1.0


class MaintenanceService(Service):
    capabilities = M.MAV_PROTOCOL_CAPABILITY_COMPASS_CALIBRATION  # DO_START_MAG_CAL and its reports

    def __init__(self, ctx, ftp_root: Path | None = None) -> None:
        self.ctx = ctx
        self.ftp_root = ftp_root
        self.slot = LongRunning()
        self.accel = AccelCal(ctx.params)
        self.accel_requester: tuple | None = None  # ((sysid, compid), channel) of the accel dialogue
        self.mag = MagCal(ctx.params)
        self.mag_outbox: dict[int, list] = {}  # channel index -> MAG_CAL messages for it
        self.prearm_display = PrearmDisplay()

    def commands(self):
        return {
            M.MAV_CMD_PREFLIGHT_CALIBRATION: self.calibration, M.MAV_CMD_STORAGE_FORMAT: self.storage_format,
            M.MAV_CMD_PREFLIGHT_STORAGE: self.storage, M.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: self.reboot,
            M.MAV_CMD_RUN_PREARM_CHECKS: self.run_prearm_checks, M.MAV_CMD_DO_START_MAG_CAL: self.start_mag_cal,
            M.MAV_CMD_DO_ACCEPT_MAG_CAL: self.accept_mag_cal, M.MAV_CMD_DO_CANCEL_MAG_CAL: self.cancel_mag_cal,
            M.MAV_CMD_FIXED_MAG_CAL_YAW: self.fixed_mag_cal_yaw, M.MAV_CMD_ACCELCAL_VEHICLE_POS: self.accelcal_vehicle_pos,
        }

    # --- calibration -------------------------------------------------------------------------
    def calibration(self, req: CommandRequest) -> int:
        if self.ctx.state.armed:
            return LATER
        p = [round(v) if math.isfinite(v) else 0 for v in (req.param1, req.param2, req.param3, req.param4, req.x, req.y)]
        if not any(p) and self.accel.running():  # QGroundControl's Cancel
            self._send_asks(self.accel.cancel())
            return ACCEPTED
        if p[4] == 1:  # the six-position dialogue: ACCEPTED, then it runs by itself
            if self.accel.running() or self.slot.job is not None:
                return LATER
            self.accel_requester = (req.inc.sender, req.inc.channel)
            self.accel.start(req.inc.now, (self.ctx.state.roll_rad, self.ctx.state.pitch_rad))
            self.ctx.wake(req.inc.channel)
            return ACCEPTED
        steps = []
        if p[0] == 1:
            steps.append(self._gyro)
        if p[2] == 1:
            steps.append(self._baro)
        if p[4] == 2:
            steps.append(self._level)
        if p[4] == 4:
            steps.append(self._simple_accel)
        if p[5] == 2:
            steps.append(self._airspeed)
        if p[3] == 1 and not any(p[:3]) and not any(p[4:]) and self.ctx.vehicle.radio_trim_sticks:
            return self._trim_radio()
        interactive = p[0] == 3 or p[1] == 1 or p[3] == 1 or p[5] == 1
        if not steps or interactive:
            return UNSUPPORTED
        if self.accel.running():
            return LATER
        self.ctx.text(M.MAV_SEVERITY_INFO, "Calibrating sensors")

        def finish() -> int:
            for step in steps:
                step()
            self._save_params()
            return ACCEPTED

        return self._long(req, CALIBRATION_S, finish)

    def _gyro(self) -> None:
        for imu, prefix in ((1, "INS_GYR"), (2, "INS_GYR2")):
            if imu == 2 and not self._param("INS_GYR2_ID", 0):
                continue
            for axis in "XYZ":
                self._set(f"{prefix}OFFS_{axis}", self._param(f"SIM_GYR{imu}_BIAS_{axis}", 0.0))
        self.ctx.text(M.MAV_SEVERITY_INFO, "Gyro calibration complete")

    def _baro(self) -> None:
        pressure_pa = _pressure_pa(self.ctx.state.alt_amsl_m)
        for n in (1, 2, 3):
            self._set(f"BARO{n}_GND_PRESS", pressure_pa)
        self.ctx.text(M.MAV_SEVERITY_INFO, "Updating barometer calibration")
        self.ctx.text(M.MAV_SEVERITY_INFO, "Barometer calibration complete")

    def _level(self) -> None:
        roll, pitch = self.ctx.state.roll_rad, self.ctx.state.pitch_rad
        self._set("AHRS_TRIM_X", roll)
        self._set("AHRS_TRIM_Y", pitch)
        self.ctx.text(M.MAV_SEVERITY_INFO, f"Trim OK: roll={math.degrees(roll):.2f} pitch={math.degrees(pitch):.2f}")

    def _simple_accel(self) -> None:
        """Offsets from one level sample, scales 1, trim 0 (ArduPilot's simple_accel_cal)."""
        for imu, prefix in ((1, "INS_ACC"), (2, "INS_ACC2")):
            if imu == 2 and not self._param("INS_ACC2_ID", 0):
                continue
            for axis in "XYZ":
                self._set(f"{prefix}OFFS_{axis}", imu_error(self.ctx.params, imu, axis)[0])
                self._set(f"{prefix}SCAL_{axis}", 1.0)
        self._set("AHRS_TRIM_X", 0.0)
        self._set("AHRS_TRIM_Y", 0.0)
        self.ctx.text(M.MAV_SEVERITY_INFO, "Accelerometer calibration complete")

    def _airspeed(self) -> None:
        self.ctx.text(M.MAV_SEVERITY_INFO, "Airspeed 1 calibrated")

    def _trim_radio(self) -> int:
        """ArduPlane's / Rover's trim_radio: each trimmed stick's RCn_TRIM becomes its current input
        (an RC override, else unchanged), at once: ACCEPTED."""
        params, override = self.ctx.params, self.ctx.state.rc_override
        for stick in self.ctx.vehicle.radio_trim_sticks:
            n = rc.mapped_channel(params, stick)
            pwm = override.get(n)
            if pwm and f"RC{n}_TRIM" in params:
                params.set(f"RC{n}_TRIM", pwm)
        self._save_params()
        return ACCEPTED

    def _param(self, name: str, default: float) -> float:
        return float(self.ctx.params.get(name)) if name in self.ctx.params else default

    def _set(self, name: str, value: float) -> None:
        if name in self.ctx.params:
            self.ctx.params.set(name, value, force=True)

    def accelcal_vehicle_pos(self, req: CommandRequest) -> int:
        result = self.accel.vehicle_pos(req.param1, req.inc.now)
        self.ctx.wake(req.inc.channel)
        return result

    def handle_COMMAND_ACK(self, inc: Incoming) -> None:
        """A ground station's COMMAND_ACK is the "press any key" of the accelerometer dialogue."""
        requester = self.accel_requester
        if requester and inc.sender == requester[0] and self.accel.key(inc.now):
            self.ctx.wake(inc.channel)

    def _send_asks(self, asks) -> None:
        if not asks or self.accel_requester is None:
            return
        (sysid, compid), channel = self.accel_requester
        for ask in asks:
            self.ctx.reply(channel, M.MAVLink_command_long_message(
                sysid, compid, M.MAV_CMD_ACCELCAL_VEHICLE_POS, 0, float(ask.position), 0, 0, 0, 0, 0, 0))
            if ask.text:
                severity = M.MAV_SEVERITY_INFO if ask.position != FAILURE else M.MAV_SEVERITY_CRITICAL
                self.ctx.text(severity, ask.text)
        if not self.accel.running():
            self._save_params()

    def _save_params(self) -> None:
        self.ctx.save_params()

    def storage_format(self, req: CommandRequest) -> int:
        if req.param1 != 1 or req.param2 != 1:
            return UNSUPPORTED
        if self.ctx.state.armed:
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
        self.ctx.text(M.MAV_SEVERITY_INFO, "Storage formatted")
        return ACCEPTED

    def _long(self, req: CommandRequest, duration_s: float, finish) -> int:
        result = self.slot.start(req.command, req.inc.sender, req.inc.channel, req.inc.now, duration_s, finish)
        self.ctx.wake(req.inc.channel)
        return result

    # --- storage, reboot, checks -------------------------------------------------------------
    def storage(self, req: CommandRequest) -> int:
        if req.param1 in (0, 1):
            return ACCEPTED
        if req.param1 != 2:
            return UNSUPPORTED
        store = self.ctx.params
        for entry in list(store.entries()):
            if not store.definition(entry.name).read_only:
                store.set(entry.name, entry.default, force=True)
        self.ctx.save_params()  # a failed write is reported later, as "Param save failed"
        self.ctx.text(M.MAV_SEVERITY_WARNING, "All parameters reset to defaults")
        return ACCEPTED

    def reboot(self, req: CommandRequest) -> int:
        what = round(req.param1) if math.isfinite(req.param1) else -1
        if what == 0:
            return ACCEPTED
        if what not in (1, 3):
            return UNSUPPORTED
        if self.ctx.state.armed:
            return FAILED
        self._reboot_now()
        return ACCEPTED

    def _reboot_now(self) -> None:
        self.ctx.text(M.MAV_SEVERITY_INFO, "Rebooting")
        self.mag.cancel()  # a reboot ends whatever calibration was running, unsaved
        self.accel.cancel()
        self.prearm_display = PrearmDisplay()
        self.ctx.autopilot.reboot()
        store = self.ctx.params
        store.set("STAT_BOOTCNT", store.get("STAT_BOOTCNT") + 1, force=True)
        self.ctx.save_params()
        self.ctx.banner()

    def run_prearm_checks(self, req: CommandRequest) -> int:
        if self.ctx.state.armed:
            return LATER
        for text in self.ctx.prearm_failures():
            self.ctx.text(M.MAV_SEVERITY_CRITICAL, f"PreArm: {text}")
        return ACCEPTED

    # --- compass calibration -----------------------------------------------------------------
    def start_mag_cal(self, req: CommandRequest) -> int:
        if self.ctx.state.armed:
            self.ctx.text(M.MAV_SEVERITY_NOTICE, "Disarm to allow compass calibration")
            return FAILED
        if not self.mag.compasses():
            return UNSUPPORTED
        delay = req.param4 if math.isfinite(req.param4) else 0.0
        result = self.mag.start(req.param1 if math.isfinite(req.param1) else -1, req.param3 != 0, delay, req.inc.now,
                                autoreboot=math.isfinite(req.x) and req.x != 0)
        if result == ACCEPTED:
            self.ctx.wake(req.inc.channel)
        return result

    def accept_mag_cal(self, req: CommandRequest) -> int:
        result = self.mag.accept(req.param1 if math.isfinite(req.param1) else -1)
        if self.mag.saved_any:
            self.mag.saved_any = False
            self._save_params()
        return result

    def cancel_mag_cal(self, req: CommandRequest) -> int:
        return self.mag.cancel()

    def fixed_mag_cal_yaw(self, req: CommandRequest) -> int:
        """FIXED_MAG_CAL_YAW: calibrate from a known heading at once (the vehicle must be still):
        every compass in use gets the simulated magnetometer's offsets."""
        compasses = self.mag.compasses()
        if self.ctx.state.armed or not compasses:
            return FAILED
        for index in compasses:
            offsets, _diag, _offdiag = self.mag.simulated_error(index)
            for name, value in zip(compass_params(index, "OFS"), offsets):
                self._set(name, value)
        self._save_params()
        self.ctx.text(M.MAV_SEVERITY_INFO, f"Mag cal from yaw {req.param1:.0f}: offsets saved")
        return ACCEPTED

    def _mag_cal_messages(self, channel, now: float) -> list:
        """MAG_CAL_PROGRESS / MAG_CAL_REPORT go to every ground station, as ArduPilot's
        gcs().send_message: whichever channel's pass finds them due sends them and leaves a copy
        for the other active channels (at most MAG_OUTBOX each)."""
        due = self.mag.messages(now) if self.mag.runs else []
        if due:
            for other in self.ctx.channels:
                if other is channel or other.policy.private or not other.peers:
                    continue
                box = self.mag_outbox.setdefault(other.index, [])
                box.extend(due)
                del box[:-MAG_OUTBOX]
                self.ctx.wake(other)
            if self.mag.saved_any:
                self.mag.saved_any = False
                self._save_params()
        if self.mag.reboot_due and not self.ctx.state.armed:
            self.mag.reboot_due = False
            self._reboot_now()
        return due + self.mag_outbox.pop(channel.index, [])

    # --- the send pass -----------------------------------------------------------------------
    def pending(self, channel, now: float, send) -> float | None:
        for ack in self.slot.due(channel, now):
            send(ack)
        if self.accel_requester is not None and self.accel_requester[1] is channel:
            self._send_asks(self.accel.poll(now))
        for msg in self._mag_cal_messages(channel, now):
            send(msg)
        if self.ctx.vehicle.can_arm:
            for text in self.prearm_display.poll(now, self.ctx.state.armed, self.ctx.prearm_failures):
                self.ctx.text(M.MAV_SEVERITY_CRITICAL, text)
        deadlines = [d for d in (self.slot.next_deadline(), self.accel.next_deadline(), self.mag.next_deadline(),
                                 self.prearm_display.next_deadline() if self.ctx.vehicle.can_arm else None)
                     if d is not None]
        return min(deadlines) if deadlines else None


def _pressure_pa(alt_amsl_m: float) -> float:
    """The simulated barometer's pressure (the standard atmosphere, as SCALED_PRESSURE)."""
    return 101325.0 * (1 - 2.25577e-5 * alt_amsl_m) ** 5.25588
