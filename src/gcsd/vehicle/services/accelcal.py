"""The six-position accelerometer calibration (ArduPilot's AP_AccelCal), pure.

Started by PREFLIGHT_CALIBRATION param5 = 1 (ACCEPTED at once, as ArduPilot answers; the
dialogue then runs by itself). States: WAITING for position n (1 level, 2 left, 3 right,
4 nose down, 5 nose up, 6 back) -> COLLECTING (SAMPLE_S) -> WAITING for n + 1 ... -> done.

While waiting, every ASK_INTERVAL_S the vehicle asks the ground station that started it
(ArduPilot's AP_AccelCal::update): COMMAND_LONG MAV_CMD_ACCELCAL_VEHICLE_POS param1 = n
(QGroundControl moves its pictures on it) and STATUSTEXT "Place vehicle <position> and press
any key." (what MAVProxy's user reads). The ground station answers either with a COMMAND_ACK
(QGroundControl's Next button, MAVProxy's Enter: "any key") or with COMMAND_LONG
MAV_CMD_ACCELCAL_VEHICLE_POS param1 = n, which is ACCEPTED when n is the position asked for and
FAILED otherwise (also when no calibration runs: ArduPilot SITL's answer to param1 0).

After the sixth sample: "Calibration successful", ACCELCAL_VEHICLE_POS_SUCCESS (16777215), and
the results in ArduPilot's parameters: INS_ACCOFFS_* / INS_ACCSCAL_* (and INS_ACC2OFFS_* /
INS_ACC2SCAL_* for the second IMU when INS_ACC2_ID is non-zero), AHRS_TRIM_X/Y from the level
sample. What it finds is the simulated IMU's error (`imu_error`): its own small factory error
(offsets 0.001 m/s/s, scale factor 1.001 on each axis, the values SITL's default parameters hold)
plus SIM_ACCn_BIAS_* and SIM_ACCn_SCAL_* where those parameters exist. (An all-zero result would
read as "never calibrated" to the pre-arm check, as on ArduPilot.)
A calibration left without an answer for IDLE_TIMEOUT_S fails ("Calibration FAILED",
ACCELCAL_VEHICLE_POS_FAILED) instead of waiting for ever; `cancel` (PREFLIGHT_CALIBRATION with
all params 0 while it runs, what QGroundControl's Cancel sends) fails it at once.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as M

ASK_INTERVAL_S = 1.0
SAMPLE_S = 0.5
IDLE_TIMEOUT_S = 120.0
POSITIONS = {1: "level", 2: "on its LEFT side", 3: "on its RIGHT side", 4: "nose DOWN", 5: "nose UP",
             6: "on its BACK"}
SUCCESS, FAILURE = M.ACCELCAL_VEHICLE_POS_SUCCESS, M.ACCELCAL_VEHICLE_POS_FAILED
FACTORY_OFFSET_MSS = 0.001
FACTORY_SCALE = 1.001


def imu_error(params, imu: int, axis: str) -> tuple[float, float]:
    """(offset m/s/s, scale) an accelerometer calibration finds on simulated IMU `imu` (1-based)."""
    bias = _get(params, f"SIM_ACC{imu}_BIAS_{axis}", 0.0)
    scale_error = _get(params, f"SIM_ACC{imu}_SCAL_{axis}", 0.0)
    scale = FACTORY_SCALE / (1.0 + scale_error) if scale_error > -1.0 else FACTORY_SCALE
    return FACTORY_OFFSET_MSS + bias, scale


@dataclass(frozen=True)
class Ask:
    """Tell the ground station which position is wanted (or SUCCESS / FAILURE), with a text."""

    position: int
    text: str | None


@dataclass
class AccelCal:
    params: object
    attitude: tuple[float, float] = (0.0, 0.0)  # roll, pitch (rad) of the vehicle at rest
    step: int = 0  # 0: not running
    collecting_until_s: float | None = None
    next_ask_s: float = 0.0
    last_answer_s: float = 0.0

    def running(self) -> bool:
        return self.step > 0

    def start(self, now: float, attitude: tuple[float, float]) -> None:
        self.step, self.collecting_until_s = 1, None
        self.next_ask_s = self.last_answer_s = now
        self.attitude = attitude

    def key(self, now: float) -> bool:
        """COMMAND_ACK from the ground station: take the sample for the position asked for."""
        if not self.running() or self.collecting_until_s is not None:
            return False
        self.collecting_until_s = now + SAMPLE_S
        self.last_answer_s = now
        return True

    def vehicle_pos(self, position: float, now: float) -> int:
        """COMMAND_LONG MAV_CMD_ACCELCAL_VEHICLE_POS from the ground station."""
        if self.running() and self.collecting_until_s is None and position == self.step:
            self.key(now)
            return M.MAV_RESULT_ACCEPTED
        return M.MAV_RESULT_FAILED

    def cancel(self) -> list[Ask]:
        if not self.running():
            return []
        self.step = 0
        return [Ask(FAILURE, "Calibration FAILED")]

    def poll(self, now: float) -> list[Ask]:
        if not self.running():
            return []
        if self.collecting_until_s is not None:
            if now < self.collecting_until_s:
                return []
            self.collecting_until_s = None
            self.step += 1
            self.last_answer_s = now
            if self.step > len(POSITIONS):
                self.step = 0
                self._save()
                return [Ask(SUCCESS, "Calibration successful")]
            self.next_ask_s = now
        if now - self.last_answer_s >= IDLE_TIMEOUT_S:
            self.step = 0
            return [Ask(FAILURE, "Calibration FAILED")]
        if now < self.next_ask_s:
            return []
        self.next_ask_s = now + ASK_INTERVAL_S
        return [Ask(self.step, f"Place vehicle {POSITIONS[self.step]} and press any key.")]

    def next_deadline(self) -> float | None:
        if not self.running():
            return None
        if self.collecting_until_s is not None:
            return self.collecting_until_s
        return min(self.next_ask_s, self.last_answer_s + IDLE_TIMEOUT_S)

    # --- results -----------------------------------------------------------------------------
    def _save(self) -> None:
        p = self.params
        for imu, prefix in ((1, "INS_ACC"), (2, "INS_ACC2")):
            if imu == 2 and not ("INS_ACC2_ID" in p and p.get("INS_ACC2_ID")):
                continue
            for axis in "XYZ":
                offset, scale = imu_error(p, imu, axis)
                _set(p, f"{prefix}OFFS_{axis}", offset)
                _set(p, f"{prefix}SCAL_{axis}", scale)
        roll, pitch = self.attitude
        _set(p, "AHRS_TRIM_X", roll)
        _set(p, "AHRS_TRIM_Y", pitch)


def _get(params, name: str, default: float) -> float:
    return float(params.get(name)) if name in params else default


def _set(params, name: str, value: float) -> None:
    if name in params:
        params.set(name, value, force=True)
