"""Parameter definitions shared by every vehicle, as data. Each one is wired to behaviour:

- SYSID_THISMAV (at the next start), SYSID_MYGCS and SYSID_ENFORCE (at once): who we are and
  which ground station may command us.
- SRn_* for each channel n: the ten stream rates, applied at once.
- ARMING_CHECK, GPS_HDOP_GOOD, BATT_ARM_VOLT, BATT_ARM_MAH, RCn_*, COMPASS_*:
  the pre-arm checks (PreArm: ... on failure). Vehicle parameters (ANGLE_MAX, WPNAV_*, FENCE_*,
  ...) are defined by each vehicle type (gcsd.vehicles).
- BATT_CAPACITY: the simulated battery. RCn_*: RC_CHANNELS values at rest. SERVOn_*: the
  scaling of SERVO_OUTPUT_RAW.
- SCHED_LOOP_RATE: the fastest message interval accepted (0.8 x the loop rate), next start.
- STAT_BOOTCNT, STAT_RUNTIME, FORMAT_VERSION: read-only, maintained by gcsd.
"""

from __future__ import annotations

from ..streams import PARAM_SUFFIX, STREAM_NAMES
from .store import INT8, INT16, INT32, REAL32, ParamDef

P = ParamDef


def sysid_params(sysid: int, gcs_sysid: int, enforce: bool) -> list[ParamDef]:
    return [
        P("SYSID_THISMAV", INT16, sysid, 1, 255, "", "MAVLink system id of this vehicle", reboot=True),
        P("SYSID_MYGCS", INT16, gcs_sysid, 1, 255, "", "System id of the ground station in control"),
        P("SYSID_ENFORCE", INT8, int(enforce), 0, 1, "", "Accept commands and writes only from SYSID_MYGCS"),
    ]


def stream_params(channel_index: int, rates: dict[str, float]) -> list[ParamDef]:
    return [
        P(f"SR{channel_index}_{PARAM_SUFFIX[s]}", INT16, int(rates[s]), 0, 50, "Hz",
          f"Stream rate of {s.upper()} on channel {channel_index}")
        for s in STREAM_NAMES
    ]


def rc_params() -> list[ParamDef]:
    out = []
    for n in range(1, 17):
        trim = 1100 if n == 3 else 1500  # throttle rests at its minimum
        out += [
            P(f"RC{n}_MIN", INT16, 1100, 800, 2200, "PWM", f"RC input {n} minimum"),
            P(f"RC{n}_MAX", INT16, 1900, 800, 2200, "PWM", f"RC input {n} maximum"),
            P(f"RC{n}_TRIM", INT16, trim, 800, 2200, "PWM", f"RC input {n} trim (value at rest)"),
            P(f"RC{n}_DZ", INT16, 30 if n <= 4 else 0, 0, 200, "PWM", f"RC input {n} dead zone"),
            P(f"RC{n}_REVERSED", INT8, 0, 0, 1, "", f"RC input {n} reversed"),
            P(f"RC{n}_OPTION", INT16, 0, 0, 1000, "", f"RC input {n} auxiliary function"),
        ]
    return out


def servo_params() -> list[ParamDef]:
    out = []
    for n in range(1, 17):
        out += [
            P(f"SERVO{n}_MIN", INT16, 1100, 800, 2200, "PWM", f"Servo output {n} minimum"),
            P(f"SERVO{n}_MAX", INT16, 1900, 800, 2200, "PWM", f"Servo output {n} maximum"),
            P(f"SERVO{n}_TRIM", INT16, 1500, 800, 2200, "PWM", f"Servo output {n} trim"),
            P(f"SERVO{n}_REVERSED", INT8, 0, 0, 1, "", f"Servo output {n} reversed"),
            P(f"SERVO{n}_FUNCTION", INT16, 33 + n - 1 if n <= 4 else 0, -1, 200, "",
              f"Servo output {n} function (33..36 motors)"),
        ]
    return out


def common_params() -> list[ParamDef]:
    return [
        P("ARMING_CHECK", INT32, 1, 0, 2**20, "", "Pre-arm checks to run: 0 none, 1 all, else a bitmask"),
        P("GPS_HDOP_GOOD", INT16, 140, 100, 900, "", "HDOP below which the GPS is good enough to arm"),
        P("BATT_CAPACITY", INT32, 5000, 0, 1_000_000, "mAh", "Battery capacity"),
        P("BATT_ARM_VOLT", REAL32, 0.0, 0.0, 100.0, "V", "Minimum battery voltage to arm (0 off)"),
        P("BATT_ARM_MAH", INT32, 0, 0, 1_000_000, "mAh", "Minimum remaining capacity to arm (0 off)"),
        P("COMPASS_USE", INT8, 1, 0, 1, "", "Use the first compass"),
        P("COMPASS_OFS_X", REAL32, 5.0, -4000, 4000, "mGauss", "Compass offset X"),
        P("COMPASS_OFS_Y", REAL32, 13.0, -4000, 4000, "mGauss", "Compass offset Y"),
        P("COMPASS_OFS_Z", REAL32, -18.0, -4000, 4000, "mGauss", "Compass offset Z"),
        P("COMPASS_OFFS_MAX", INT16, 1800, 500, 3000, "", "Largest compass offset allowed to arm"),
        P("SCHED_LOOP_RATE", INT16, 400, 50, 2000, "Hz", "Loop rate; messages may go at 0.8 x this", reboot=True),
        P("STAT_BOOTCNT", INT16, 0, 0, 32767, "", "Number of starts", read_only=True),
        P("STAT_RUNTIME", INT32, 0, 0, 2**31 - 1, "s", "Total time running", read_only=True),
        P("FORMAT_VERSION", INT16, 120, 0, 32767, "", "Parameter storage format", read_only=True),
    ]


def base_params(sysid: int, gcs_sysid: int, enforce: bool, channel_rates: list[dict[str, float]]) -> list[ParamDef]:
    defs = sysid_params(sysid, gcs_sysid, enforce) + common_params() + rc_params() + servo_params()
    for index, rates in enumerate(channel_rates):
        defs += stream_params(index, rates)
    return defs
