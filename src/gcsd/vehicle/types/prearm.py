"""Pre-arm checks as a table: each check is a function of the node returning failure texts.

A vehicle type lists the checks it runs (`VehicleType.prearm_checks`); arming reports each
failure as "PreArm: <text>" and is refused unless forced. ARMING_CHECK selects them as
ArduPilot's bitmask does: 0 none, 1 all, else the bits below. The fence check runs whenever
ARMING_CHECK is not 0 (ArduPilot does not let it be skipped either).

| check | bit | fails when |
|---|---|---|
| angle_max | 32 (parameters) | ANGLE_MAX outside 1000..8000 cdeg (10..80 degrees) |
| gps | 8 | no 3D fix, or HDOP above GPS_HDOP_GOOD / 100 |
| battery | 256 | voltage below BATT_ARM_VOLT, remaining below BATT_ARM_MAH, below 10 %, or already low |
| rc_calibration | 64 | RC1..4 MIN above 1300, MAX below 1700, TRIM outside MIN..MAX |
| compass | 4 | a compass in use (COMPASS_DEV_IDn, COMPASS_USEn) with all offsets 0 (never calibrated), or one beyond COMPASS_OFFS_MAX |
| accelerometers | 16 (INS) | an accelerometer present (INS_ACCn_ID) with INS_ACCnOFFS all 0 or a zero INS_ACCnSCAL (never calibrated) |
| safety_switch | 2048 | the safety switch is on (DO_SET_SAFETY_SWITCH_STATE) |
| fence | always | fence enabled and the vehicle outside it, or FENCE_MARGIN >= FENCE_RADIUS |
"""

from __future__ import annotations

from gcsd.vehicle.autopilot import fence as fence_check

ALL = 1
BIT_COMPASS = 4
BIT_GPS = 8
BIT_PARAMETERS = 32
BIT_RC = 64
BIT_BATTERY = 256
BIT_INS = 16
BIT_SWITCH = 2048
LOW_BATTERY_PCT = 10


def _enabled(ctx, bit: int) -> bool:
    mask = int(ctx.params.get("ARMING_CHECK"))
    return mask & ALL or mask & bit


def angle_max(ctx) -> list[str]:
    if not _enabled(ctx, BIT_PARAMETERS):
        return []
    return [] if 1000 <= ctx.params.get("ANGLE_MAX") <= 8000 else ["Check ANGLE_MAX"]


def gps(ctx) -> list[str]:
    if not _enabled(ctx, BIT_GPS):
        return []
    s = ctx.state
    if s.gps_fix_type < 3:
        return ["Need 3D Fix"]
    if "GPS_HDOP_GOOD" not in ctx.params:  # ArduCopter's; the other types have no HDOP check
        return []
    limit = ctx.params.get("GPS_HDOP_GOOD") / 100.0
    if s.hdop > limit:
        return [f"High GPS HDOP ({s.hdop:.2f} > {limit:.2f})"]
    return []


def battery(ctx) -> list[str]:
    if not _enabled(ctx, BIT_BATTERY) or ("BATT_MONITOR" in ctx.params and ctx.params.get("BATT_MONITOR") == 0):
        return []  # no battery monitor, no battery checks
    p, s = ctx.params.get, ctx.state
    out = []
    if p("BATT_ARM_VOLT") > 0 and s.battery_voltage_v < p("BATT_ARM_VOLT"):
        out.append(f"Battery below minimum arming voltage ({s.battery_voltage_v:.1f}V)")
    if p("BATT_ARM_MAH") > 0 and s.capacity_mah - s.consumed_mah < p("BATT_ARM_MAH"):
        out.append("Battery below minimum arming capacity")
    if s.battery_remaining_pct < LOW_BATTERY_PCT:
        out.append(f"Battery below minimum ({s.battery_remaining_pct}%)")
    if "BATT_LOW_VOLT" in ctx.params and 0 < p("BATT_LOW_VOLT") and s.battery_voltage_v < p("BATT_LOW_VOLT"):
        out.append(f"Battery 1 low voltage failsafe ({s.battery_voltage_v:.1f}V)")
    return out


def rc_calibration(ctx) -> list[str]:
    if not _enabled(ctx, BIT_RC):
        return []
    p = ctx.params.get
    out = []
    for n in range(1, 5):
        lo, hi, trim = p(f"RC{n}_MIN"), p(f"RC{n}_MAX"), p(f"RC{n}_TRIM")
        if lo > 1300:
            out.append(f"RC{n}_MIN too high")
        elif hi < 1700:
            out.append(f"RC{n}_MAX too low")
        elif not lo <= trim <= hi:
            out.append(f"RC{n}_TRIM out of range")
    return out


def _compasses_in_use(ctx) -> list[int]:
    """Compass indices with a device (COMPASS_DEV_IDn != 0) used for yaw (COMPASS_USEn)."""
    params = ctx.params
    out = []
    for i, suffix in enumerate(("", "2", "3")):
        dev, use = f"COMPASS_DEV_ID{suffix}", f"COMPASS_USE{suffix}"
        if use not in params or not params.get(use):
            continue
        if dev in params and not params.get(dev):
            continue
        if f"COMPASS_OFS{suffix}_X" in params:
            out.append(i)
    return out


def compass(ctx) -> list[str]:
    """ArduPilot's compass checks: a compass in use with all-zero offsets was never calibrated
    ("Compass not calibrated", what a fresh board says until the compass calibration ran), and
    offsets beyond COMPASS_OFFS_MAX are too high."""
    if not _enabled(ctx, BIT_COMPASS):
        return []
    p = ctx.params.get
    limit = p("COMPASS_OFFS_MAX") if "COMPASS_OFFS_MAX" in ctx.params else 1800
    for i in _compasses_in_use(ctx):
        suffix = "" if i == 0 else str(i + 1)
        offsets = [abs(p(f"COMPASS_OFS{suffix}_{axis}")) for axis in "XYZ"]
        if not any(offsets):
            return ["Compass not calibrated"]
        if max(offsets) > limit:
            return ["Compass offsets too high"]
    return []


def accelerometers(ctx) -> list[str]:
    """ArduPilot's accel_calibrated_ok_all: every accelerometer present (INS_ACCn_ID != 0) needs
    offsets that are not all zero and scales that are not zero, else "3D Accel calibration needed"
    (the accelerometer calibration writes them)."""
    if not _enabled(ctx, BIT_INS):
        return []
    params = ctx.params
    for imu, prefix in ((1, "INS_ACC"), (2, "INS_ACC2"), (3, "INS_ACC3")):
        ident = "INS_ACC_ID" if imu == 1 else f"INS_ACC{imu}_ID"
        if ident not in params or not params.get(ident) or f"{prefix}OFFS_X" not in params:
            continue
        offsets = [params.get(f"{prefix}OFFS_{axis}") for axis in "XYZ"]
        scales = [params.get(f"{prefix}SCAL_{axis}") for axis in "XYZ"]
        if not any(offsets) or not all(scales):
            return ["3D Accel calibration needed"]
    return []


def safety_switch(ctx) -> list[str]:
    """The safety switch is on (DO_SET_SAFETY_SWITCH_STATE 0: safe): the outputs are held off."""
    if not _enabled(ctx, BIT_SWITCH):
        return []
    on = ctx.state.safety_on
    return ["Hardware safety switch"] if on else []


def fence(ctx) -> list[str]:
    if "FENCE_ENABLE" not in ctx.params or not ctx.params.get("FENCE_ENABLE"):
        return []
    config = fence_check.FenceConfig.from_params(ctx.params.get)  # Blimp 4.6 has no FENCE_TYPE: no circle
    if config.types & fence_check.CIRCLE and config.margin_m >= config.radius_m:
        return ["Fence: FENCE_MARGIN is not less than FENCE_RADIUS"]
    if ctx.state.gps_fix_type < 3:
        return ["Fence requires position"]
    breach = fence_check.breaches(ctx.state, config, ctx.plans.fence.stored(), ignore_min_alt=True)
    return [f"Fence: vehicle outside the {fence_check.describe(breach)}"] if breach else []


FLYING_CHECKS = (gps, battery, rc_calibration, compass, accelerometers, safety_switch, fence)
DRIVING_CHECKS = FLYING_CHECKS
TRACKER_CHECKS = (gps, battery, compass)


def prearm_failures(ctx) -> list[str]:
    """Every failing check of the node's vehicle type (ARMING_CHECK 0: none)."""
    if "ARMING_CHECK" not in ctx.params or ctx.params.get("ARMING_CHECK") == 0:
        return []  # a type without ARMING_CHECK (AntennaTracker, a companion) has no arming checks
    failures: list[str] = []
    for check in ctx.vehicle.prearm_checks:
        failures += check(ctx)
    backend_checks = getattr(ctx.autopilot, "backend_prearm_failures", None)
    if backend_checks is not None:
        failures += backend_checks()
    return failures


class PrearmDisplay:
    """ArduPilot's AP_Arming::update while disarmed: the checks run once a second, and their
    failures are shown as "PreArm: ..." STATUSTEXT every DISPLAY_PERIOD_S, or at once (at most every
    CHANGE_GAP_S) when the set of failures changes; nothing while they pass or while armed. Pure:
    `poll(now, armed, failures)` returns the texts to send now; `failures` is called only when due."""

    CHECK_INTERVAL_S = 1.0
    DISPLAY_PERIOD_S = 30.0
    CHANGE_GAP_S = 4.0

    def __init__(self) -> None:
        self.next_check_s = 0.0
        self.last_display_s: float | None = None
        self.last_failures: list[str] = []

    def poll(self, now: float, armed: bool, failures) -> list[str]:
        if armed:  # nothing to do until disarmed: the next look is a check interval away
            self.last_failures = []
            self.next_check_s = now + self.CHECK_INTERVAL_S
            return []
        if now < self.next_check_s:
            return []
        self.next_check_s = now + self.CHECK_INTERVAL_S
        found = failures()
        changed = found != self.last_failures
        self.last_failures = found
        if not found:
            return []
        since = None if self.last_display_s is None else now - self.last_display_s
        if since is None or since >= self.DISPLAY_PERIOD_S or (changed and since >= self.CHANGE_GAP_S):
            self.last_display_s = now
            return [f"PreArm: {text}" for text in found]
        return []

    def next_deadline(self) -> float:
        return self.next_check_s
