"""Parity of gcsd's parameter sets with ArduPilot: the PARAM_VALUE list a copter, plane or rover
serves with the default configuration equals ArduPilot SITL's (the captures, copied to
tests/integration/data/ardupilot/*-params.tsv) mapped to 4.6, in names, order, types and values.

The oracle here is written from the captures' README alone, not from the build script
(tools/param_data.py): MAV{n}_X -> SR{n-1}_X, MAV_SYSID -> SYSID_THISMAV, MAV_GCS_SYSID ->
SYSID_MYGCS, MAV_TELEM_DELAY -> TELEM_DELAY, MAV_OPTIONS -> SYSID_ENFORCE (AP_Int8 in 4.6), and
MAV{n}_OPTIONS plus the 4.7 additions below are not 4.6 parameters. The documented differences:

- SIM_*: gcsd is not SITL. Of SITL's simulator parameters it serves the eight its simulation
  honours, under 4.6 SITL's names: SIM_SPEEDUP, SIM_RATE_HZ (25: gcsd's physics steps per
  second, SITL's 1200 is its own loop), SIM_WIND_SPD/_DIR/_TURB, and 4.6's single-GPS
  SIM_GPS_DISABLE, SIM_GPS_NUMSATS, SIM_GPS_HDOP where 4.7 has SIM_GPS1_ENABLE/_NUMSATS/_ACC.
- SR0_*: the configuration's stream rates for channel 0 (SPEC.md's YAML contract), not the
  capture's (which are the SITL serial port's).
- STAT_BOOTCNT: the firmware default 0; the capture's 1 is after SITL's first boot, and a
  daemon's first start counts to 1 too (tests/integration/test_param_parity.py).
"""

from __future__ import annotations

import math
import re
import struct
from pathlib import Path

import pytest

from gcsd.config import DEFAULT_STREAM_RATES_HZ
from gcsd.vehicle.params import INT8, INT16, INT32, REAL32, ParamStore, SetResult, parameter_set
from gcsd.vehicle.types import VEHICLE_TYPES, vehicle_params
from gcsd.wire.streams import PARAM_SUFFIX

CAPTURES = Path(__file__).resolve().parents[1] / "integration" / "data" / "ardupilot"  # copies of the captures
TYPES = {"INT8": INT8, "INT16": INT16, "INT32": INT32, "REAL32": REAL32}
RENAMED = {"MAV_SYSID": "SYSID_THISMAV", "MAV_GCS_SYSID": "SYSID_MYGCS", "MAV_TELEM_DELAY": "TELEM_DELAY",
           "MAV_OPTIONS": "SYSID_ENFORCE"}
TYPE_46 = {"SYSID_ENFORCE": "INT8"}
ADDED_IN_4_7 = {  # captured names that ArduPilot's 4.6 metadata (ParameterRepository) does not have
    "copter": {"INS_HNTC3_ENABLE", "THROW_ALT_DCSND", "THROW_ALT_ACSND", "FSTRATE_ENABLE", "FSTRATE_DIV",
               "FENCE_NTF_FREQ"},
    "plane": {"ALT_SLOPE_MIN", "ALT_SLOPE_MAXHGT", "TKOFF_THR_IDLE", "INS_HNTC3_ENABLE", "TECS_THR_ERATE",
              "FWD_BAT_THR_CUT", "AUTOLAND_WP_ALT", "AUTOLAND_WP_DIST", "AUTOLAND_DIR_OFF", "AUTOLAND_OPTIONS",
              "AUTOLAND_CLIMB", "FENCE_NTF_FREQ"},
    "rover": {"INS_HNTC3_ENABLE", "ARMING_NEED_LOC", "MOT_REV_DELAY", "ATC_STR_DEC_MAX", "FENCE_OPTIONS",
              "FENCE_NTF_FREQ"},
}
SIM_SERVED = {"SIM_SPEEDUP", "SIM_RATE_HZ", "SIM_WIND_SPD", "SIM_WIND_DIR", "SIM_WIND_TURB"}
SIM_GPS = {"SIM_GPS1_ENABLE": ("SIM_GPS_DISABLE", "INT8", 0.0), "SIM_GPS1_NUMSATS": ("SIM_GPS_NUMSATS", "INT8", None),
           "SIM_GPS1_ACC": ("SIM_GPS_HDOP", "REAL32", 0.7)}
SIM_VALUES = {"SIM_RATE_HZ": 25.0}
FIRMWARE_DEFAULTS = {"STAT_BOOTCNT": 0.0}  # the capture's 1 counts SITL's first boot; gcsd counts its own



def f32(value: float) -> float:
    return struct.unpack("<f", struct.pack("<f", value))[0]


def capture_as_46(vehicle: str) -> list[tuple[str, str, float]]:
    """The SITL capture mapped to 4.6, with gcsd's documented differences applied."""
    out = []
    for line in (CAPTURES / f"{vehicle}-params.tsv").read_text().splitlines():
        if line.startswith("#"):
            continue
        name, ptype, value = line.split("\t")
        if name in SIM_GPS:
            new, new_type, new_value = SIM_GPS[name]
            out.append((new, new_type, float(value) if new_value is None else new_value))
            continue
        if name.startswith("SIM_") and name not in SIM_SERVED:
            continue
        if name in ADDED_IN_4_7[vehicle] or re.fullmatch(r"MAV\d+_OPTIONS", name):
            continue
        m = re.fullmatch(r"MAV(\d+)_(\w+)", name)
        name = f"SR{int(m.group(1)) - 1}_{m.group(2)}" if m else RENAMED.get(name, name)
        value = FIRMWARE_DEFAULTS.get(name, SIM_VALUES.get(name, float(value)))
        out.append((name, TYPE_46.get(name, ptype), value))
    for stream, rate in DEFAULT_STREAM_RATES_HZ.items():  # channel 0's configured stream rates
        sr0 = f"SR0_{PARAM_SUFFIX[stream]}"
        out = [(n, t, float(rate) if n == sr0 else v) for n, t, v in out]
    return out


def served(vehicle: str) -> ParamStore:
    """A vehicle's store as the daemon builds it with the default configuration (one channel)."""
    return ParamStore(vehicle_params(VEHICLE_TYPES[vehicle], 1, 255, False, [dict(DEFAULT_STREAM_RATES_HZ)], 1.0))


@pytest.mark.parametrize("vehicle", ["copter", "plane", "rover"])
def test_the_param_value_list_equals_the_sitl_capture_mapped_to_4_6(vehicle):
    expected = capture_as_46(vehicle)
    store = served(vehicle)
    got = [(e.name, e.ptype, e.value) for e in store.entries()]
    assert [g[0] for g in got] == [e[0] for e in expected]  # names and order
    assert [g[1] for g in got] == [TYPES[e[1]] for e in expected]  # types
    wrong = [(g[0], g[2], e[2]) for g, e in zip(got, expected, strict=True) if f32(g[2]) != f32(e[2])]
    assert wrong == []  # values, as PARAM_VALUE carries them
    assert len(store) == {"copter": 1000, "plane": 1046, "rover": 885}[vehicle]


def test_names_qgroundcontrol_reads_for_a_copter_exist_with_ardupilots_types():
    """Issue 12's list of what QGroundControl's ArduPilot pages read, and the types MAVSDK checks."""
    store = served("copter")
    wanted = ["FRAME_CLASS", "FRAME_TYPE", *(f"FLTMODE{n}" for n in range(1, 7)), "FLTMODE_CH", "RCMAP_ROLL",
              "RCMAP_PITCH", "RCMAP_THROTTLE", "RCMAP_YAW", "INS_ACCOFFS_X", "INS_ACCSCAL_Z", "COMPASS_DEV_ID",
              "COMPASS_OFS2_X", "COMPASS_OFS3_Z", "BATT_MONITOR", "FS_THR_ENABLE", "FS_THR_VALUE", "FS_OPTIONS",
              "ATC_RAT_RLL_P", "PSC_POSXY_P", "MOT_SPIN_ARM", "MOT_SPIN_MIN", "MOT_SPIN_MAX", "MOT_PWM_MIN",
              "MOT_PWM_MAX", "SYSID_THISMAV", "SR0_EXTRA1", "DISARM_DELAY", "PILOT_TKOFF_ALT"]
    assert [n for n in wanted if n not in store] == []
    for name in ("WPNAV_SPEED", "WPNAV_SPEED_UP", "WPNAV_SPEED_DN", "WPNAV_RADIUS", "WPNAV_ACCEL", "LOIT_SPEED"):
        assert store.definition(name).ptype == REAL32, name


@pytest.mark.parametrize("vehicle", sorted(VEHICLE_TYPES))
def test_every_set_loads_and_every_default_is_inside_its_range(vehicle):
    defs = parameter_set(VEHICLE_TYPES[vehicle].parameter_set())
    assert len({d.name for d in defs}) == len(defs) > 40
    for d in defs:
        assert d.min is None or d.min <= d.default, d
        assert d.max is None or d.default <= d.max, d
        assert len(d.name) <= 16 and not (d.ptype == REAL32 and math.isnan(d.default)), d


def test_a_value_outside_the_documented_range_is_stored_as_ardupilot_stores_it():
    store = served("copter")
    d = store.definition("ANGLE_MAX")
    assert (d.min, d.max, d.units) == (1000, 8000, "cdeg")  # ArduPilot 4.6's @Range and @Units
    assert store.set("ANGLE_MAX", 9000.0) is SetResult.CHANGED
    assert (store.get("ANGLE_MAX"), store.clamped("ANGLE_MAX")) == (9000, 8000)
    assert store.set("COMPASS_CAL_FIT", 100.0) is SetResult.CHANGED  # QGroundControl's compass dialogue
    assert store.set("ANGLE_MAX", 3000.0) is SetResult.CHANGED
    assert store.set("MOT_SPIN_ARM", f32(0.2)) is SetResult.CHANGED  # the top of 0..0.2, as float32 sends it
    for entry in store.entries():  # QGroundControl's "reset to defaults" writes each default back
        if not store.definition(entry.name).read_only:
            assert store.set(entry.name, entry.default) in (SetResult.UNCHANGED, SetResult.CHANGED), entry


def test_read_only_parameters_are_arduPilots_internal_ones():
    store = served("copter")
    assert store.definition("COMPASS_DEV_ID").read_only and store.definition("INS_ACC_ID").read_only
    assert store.set("COMPASS_DEV_ID", 1.0) is SetResult.READ_ONLY
    assert not store.definition("COMPASS_OFS_X").read_only


def test_the_configuration_decides_sysids_and_stream_rates_and_extra_channels_get_their_sr_group():
    rates = dict(DEFAULT_STREAM_RATES_HZ, extra1=20)
    defs = vehicle_params(VEHICLE_TYPES["copter"], 7, 250, True, [rates] * 5, 2.0)
    store = ParamStore(defs)
    assert (store.get("SYSID_THISMAV"), store.get("SYSID_MYGCS"), store.get("SYSID_ENFORCE")) == (7, 250, 1)
    assert store.get("SIM_SPEEDUP") == 2.0
    assert [store.get(f"SR{n}_EXTRA1") for n in range(5)] == [20] * 5
    names = [d.name for d in defs]
    assert names.index("SR3_RAW_SENS") == names.index("SR2_ADSB") + 1  # after ArduPilot's last SR group
    assert store.definition("SR4_EXTRA1").ptype == INT16 and store.definition("SR4_EXTRA1").max == 50


# --- docs/parameters.md: the acting parameters, and the counts it states ------------------------

DOC = Path(__file__).resolve().parents[2] / "docs" / "parameters.md"


def expand(pattern: str) -> list[str]:
    """Braces as in a shell: RC{1..3}_MIN, COMPASS_OFS{,2}_{X,Y}."""
    m = re.search(r"\{([^{}]*)\}", pattern)
    if m is None:
        return [pattern]
    body = m.group(1)
    if ".." in body:
        lo, hi = body.split("..")
        options = [str(i) for i in range(int(lo), int(hi) + 1)]
    else:
        options = body.split(",")
    return [name for option in options
            for name in expand(pattern[:m.start()] + option + pattern[m.end():])]


def acting_names(vehicle: str | None = None) -> set[str]:
    """The names the docs' table says act (for `vehicle`: the rows naming it or "all")."""
    section = DOC.read_text().split("## Parameters that act", 1)[1].split("<!-- acting-counts -->", 1)[0]
    names: set[str] = set()
    for line in section.splitlines():
        if not line.startswith("| `"):
            continue
        cells = line.split("|")
        types = {t.strip() for t in cells[2].split(",")}
        if vehicle is None or vehicle in types or "all" in types:
            for token in re.findall(r"`([A-Z0-9_{},.]+)`", cells[1]):
                names.update(expand(token))
    return names


def stated_counts() -> dict[str, tuple[int, int]]:
    block = DOC.read_text().split("<!-- acting-counts -->", 1)[1].split("<!-- /acting-counts -->", 1)[0]
    rows = [r.split("|")[1:4] for r in block.splitlines() if r.split("|")[2:3] and r.split("|")[2].strip().isdigit()]
    return {t.strip(): (int(s), int(a)) for t, s, a in rows}


def test_every_acting_parameter_the_docs_name_is_ardupilots():
    every = set().union(*({d.name for d in parameter_set(v.parameter_set())} for v in VEHICLE_TYPES.values()))
    assert sorted(acting_names() - every) == []
    for name, v in VEHICLE_TYPES.items():  # what a vehicle's settings read is in the docs' rows for it
        assert sorted(set(v.params) - acting_names(name)) == [], name


def test_the_docs_state_the_served_and_acting_counts_of_each_type():
    counts = {}
    for name, v in VEHICLE_TYPES.items():
        acting = acting_names(name)
        store = ParamStore(vehicle_params(v, 1, 255, False, [dict(DEFAULT_STREAM_RATES_HZ)], 1.0))
        counts[name] = (len(store), sum(1 for e in store.entries() if e.name in acting))
    assert stated_counts() == counts


@pytest.mark.parametrize("vehicle", sorted(VEHICLE_TYPES))
def test_every_vehicle_type_serves_its_whole_set_after_its_banner(tmp_path, vehicle):
    from pymavlink.dialects.v20 import ardupilotmega as M
    from vehicle_harness import Harness

    h = Harness(tmp_path, vehicle=vehicle)
    mark = h.mark()
    h.send(M.MAVLink_param_request_list_message(h.node.sysid, 1))
    h.run(1.0, step=0.01)  # the list goes at 25 values per 10 ms
    values = h.of_type("PARAM_VALUE", mark)
    assert sorted(v.param_index for v in values) == list(range(len(h.node.params)))
    firmware = h.node.vehicle.firmware
    banner = h.texts(mark)[0]
    assert banner == (f"{firmware} V4.6.3 (3fc7011a)" if firmware else "gcsd 0.1.0 (companion computer)")
