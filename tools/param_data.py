"""Build gcsd's parameter data (src/gcsd/params/data/*.tsv) from facts about ArduPilot. Run once.

Inputs (none of them code):
- the SITL captures in ../shared/ardupilot/{copter,plane,rover}-params.tsv: name, MAV_PARAM_TYPE
  and value of every parameter in index order (ArduPilot master, V4.7.0-dev);
- ArduPilot's published 4.x metadata, ArduPilot/ParameterRepository `<Vehicle>-<x.y>/apm.pdef.json`
  (ranges, values, units, display names, ReadOnly, RebootRequired).

    python tools/param_data.py CAPTURE_DIR METADATA_DIR   # METADATA_DIR/Copter-4.6.json ...

What it decides (docs/parameters.md says the same for users):
- The captures are mapped to 4.6 as ../shared/ardupilot/README.md says: MAV{n}_X -> SR{n-1}_X,
  MAV_SYSID -> SYSID_THISMAV, MAV_GCS_SYSID -> SYSID_MYGCS, MAV_TELEM_DELAY -> TELEM_DELAY,
  MAV_OPTIONS -> SYSID_ENFORCE (4.6 declares it AP_Int8: INT8); MAV{n}_OPTIONS is dropped.
  A captured name that the 4.6 metadata does not know is a 4.7 addition and is dropped.
- SIM_*: gcsd is not SITL; the capture's ~100 SITL simulator parameters are dropped, except the
  eight gcsd's own simulation honours, under their 4.6 SITL names: SIM_SPEEDUP, SIM_RATE_HZ,
  SIM_WIND_SPD, SIM_WIND_DIR, SIM_WIND_TURB (as captured) and SIM_GPS_DISABLE, SIM_GPS_NUMSATS,
  SIM_GPS_HDOP (4.6's single-GPS names, placed where 4.7's SIM_GPS1_* are). SITL publishes no
  metadata for them, so their ranges are gcsd's (what its simulation can do). SIM_RATE_HZ is 25
  (gcsd's physics steps per real second; SITL's 1200 is its own loop).
- Defaults are the captured values (SITL's defaults files included: FRAME_CLASS, BATT_MONITOR,
  RC and compass settings of a simulated vehicle). gcsd replaces a few at run time from its
  configuration (SYSID_*, SRn_*, SIM_SPEEDUP): gcsd.vehicle.params.defs.
- Ranges: the metadata's Range; else the span of its Values (numeric keys); else none (the C
  type's range). A range is widened to include the default (SITL's defaults files set a few
  values outside the documented range; writing the default back must work).
- Other vehicle types: the parameters of that type's metadata (Sub-4.5: ArduSub has no 4.6;
  Tracker-4.6; Blimp-4.7: Blimp's only published set) that exist in a captured vehicle, with
  that vehicle's type and value (copter first, then rover, then plane), in the capture's order;
  plus the type's own parameters gcsd acts on that no capture has (types from gcsd's vehicle
  module). Companion: the identity, stream-rate, statistics and scheduler parameters of the
  common libraries (a companion computer is not an ArduPilot vehicle; these are what it honours).
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

RENAME = {"MAV_SYSID": "SYSID_THISMAV", "MAV_GCS_SYSID": "SYSID_MYGCS", "MAV_TELEM_DELAY": "TELEM_DELAY",
          "MAV_OPTIONS": "SYSID_ENFORCE"}
TYPE_46 = {"SYSID_ENFORCE": "INT8"}  # AP_Int8 sysid_enforce in 4.6 (4.7's MAV_OPTIONS is AP_Int16)
SIM_KEEP = {"SIM_SPEEDUP", "SIM_RATE_HZ", "SIM_WIND_SPD", "SIM_WIND_DIR", "SIM_WIND_TURB"}
SIM_GPS_46 = {  # 4.7 name in the capture -> 4.6 SITL name, type, gcsd's value
    "SIM_GPS1_ENABLE": ("SIM_GPS_DISABLE", "INT8", "0"),
    "SIM_GPS1_NUMSATS": ("SIM_GPS_NUMSATS", "INT8", None),
    "SIM_GPS1_ACC": ("SIM_GPS_HDOP", "REAL32", "0.7"),
}
SIM_RANGES = {  # gcsd's simulation limits (no published metadata for SITL parameters)
    "SIM_SPEEDUP": ("0.01", "1000", "", "Simulation time multiplier"),
    "SIM_RATE_HZ": ("1", "400", "Hz", "Simulation steps per real second"),
    "SIM_WIND_SPD": ("0", "40", "m/s", "Simulated wind speed"),
    "SIM_WIND_DIR": ("0", "360", "deg", "Direction the simulated wind blows from"),
    "SIM_WIND_TURB": ("0", "10", "m/s", "Simulated gust amplitude"),
    "SIM_GPS_DISABLE": ("0", "1", "", "1: the simulated GPS has no fix"),
    "SIM_GPS_NUMSATS": ("0", "40", "", "Satellites the simulated GPS sees (< 4: no fix)"),
    "SIM_GPS_HDOP": ("0.1", "99", "", "HDOP of the simulated GPS"),
}
SIM_VALUES = {"SIM_RATE_HZ": "25"}
# STAT_BOOTCNT: the capture's 1 is after SITL's first boot; the firmware default is 0, and gcsd
# counts its own starts from there (its first start shows 1, as the capture).
COUNTED = {"STAT_BOOTCNT": "0"}
READ_ONLY_GCSD = {"STAT_BOOTCNT", "STAT_RUNTIME", "FORMAT_VERSION"}  # maintained by gcsd
# The other types' own parameters gcsd acts on that no capture has: name -> (type, default).
OWN = {
    "tracker": {"YAW_SLEW_TIME": ("REAL32", "2.0"), "PITCH_SLEW_TIME": ("REAL32", "2.0"),
                "PITCH_MIN": ("INT16", "-90"), "PITCH_MAX": ("INT16", "90"), "SCAN_SPEED_YAW": ("INT16", "2"),
                "SYSID_TARGET": ("INT16", "0")},
    "blimp": {"MAX_VEL_XY": ("REAL32", "1.5"), "MAX_VEL_Z": ("REAL32", "0.5"), "MAX_VEL_YAW": ("REAL32", "20.0"),
              "MAX_POS_XY": ("REAL32", "5.0")},
    "sub": {},
}
OTHER_META = {"sub": "Sub-4.5", "tracker": "Tracker-4.6", "blimp": "Blimp-4.7"}
COMPANION_PREFIXES = ("SYSID_", "TELEM_DELAY", "STAT_", "SCHED_", "FORMAT_VERSION")
COMPANION_SR = re.compile(r"SR\d+_")


def read_capture(path: Path) -> list[tuple[str, str, str]]:
    out = []
    for line in path.read_text().splitlines():
        if line.startswith("#") or not line.strip():
            continue
        name, ptype, value = line.split("\t")
        out.append((name, ptype, value))
    return out


def read_meta(path: Path) -> dict[str, dict]:
    meta = {}
    for group in json.loads(path.read_text()).values():
        if isinstance(group, dict):
            meta.update({n: i for n, i in group.items() if isinstance(i, dict)})
    return meta


def to_46(name: str) -> str | None:
    if name in RENAME:
        return RENAME[name]
    m = re.fullmatch(r"MAV(\d+)_(\w+)", name)
    if m:
        return None if m.group(2) == "OPTIONS" else f"SR{int(m.group(1)) - 1}_{m.group(2)}"
    return name


def known(name: str, meta: dict) -> bool:
    """In this metadata under its 4.6 name or, for a 4.7 set (Blimp-4.7), its 4.7 name."""
    if name in meta:
        return True
    back = {v: k for k, v in RENAME.items()} | {"ARMING_CHECK": "ARMING_SKIPCHK"}  # 4.7 renames
    m = re.fullmatch(r"SR(\d+)_(\w+)", name)
    return back.get(name, f"MAV{int(m.group(1)) + 1}_{m.group(2)}" if m else name) in meta


def mapped(capture, meta) -> list[tuple[str, str, str]]:
    out = []
    for name, ptype, value in capture:
        if name in SIM_GPS_46:
            new, new_type, new_value = SIM_GPS_46[name]
            out.append((new, new_type, new_value if new_value is not None else value))
            continue
        if name.startswith("SIM_"):
            if name in SIM_KEEP:
                out.append((name, ptype, SIM_VALUES.get(name, value)))
            continue
        new = to_46(name)
        if new is None or new not in meta:
            continue
        out.append((new, TYPE_46.get(new, ptype), COUNTED.get(new, value)))
    return out


def _num(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def row(name: str, ptype: str, value: str, info: dict | None) -> str:
    info = info or {}
    lo = hi = None
    if "Range" in info:
        lo, hi = _num(info["Range"]["low"]), _num(info["Range"]["high"])
    elif "Values" in info:
        keys = [k for k in (_num(k) for k in info["Values"]) if k is not None]
        if keys:
            lo, hi = min(keys), max(keys)
    units, display = info.get("Units", ""), info.get("DisplayName", "")
    if name in SIM_RANGES:
        lo_s, hi_s, units, display = SIM_RANGES[name]
        lo, hi = float(lo_s), float(hi_s)
    default = float(value)
    if lo is not None and hi is not None:
        if lo > hi:
            lo, hi = hi, lo
        lo, hi = min(lo, default), max(hi, default)
    flags = ""
    if info.get("RebootRequired") == "True":
        flags += "R"
    if info.get("ReadOnly") == "True" or name in READ_ONLY_GCSD:
        flags += "O"
    fmt = lambda x: "" if x is None else (str(int(x)) if x == int(x) else repr(x))
    clean = lambda s: " ".join(str(s).split())
    return "\t".join((name, ptype, value, fmt(lo), fmt(hi), flags, clean(units), clean(display)))


HEADER = ("# gcsd parameter set: {what}. Generated by tools/param_data.py; see docs/parameters.md.\n"
          "# name\ttype\tdefault\tmin\tmax\tflags (R reboot, O read-only)\tunits\tdisplay name\n")


def write(out_dir: Path, vehicle: str, what: str, rows: list[str]) -> None:
    (out_dir / f"{vehicle}.tsv").write_text(HEADER.format(what=what) + "\n".join(rows) + "\n")
    print(f"{vehicle}: {len(rows)} parameters")


def main(capture_dir: Path, meta_dir: Path, out_dir: Path) -> None:
    sets: dict[str, list[tuple[str, str, str]]] = {}
    metas = {}
    for vehicle, release in (("copter", "Copter-4.6"), ("plane", "Plane-4.6"), ("rover", "Rover-4.6")):
        meta = read_meta(meta_dir / f"{release}.json")
        metas[vehicle] = meta
        sets[vehicle] = mapped(read_capture(capture_dir / f"{vehicle}-params.tsv"), meta)
        write(out_dir, vehicle, f"ArduPilot {release} (SITL capture mapped to 4.6)",
              [row(n, t, v, meta.get(n)) for n, t, v in sets[vehicle]])
    for vehicle, release in OTHER_META.items():
        meta = read_meta(meta_dir / f"{release}.json")
        seen: set[str] = set()
        rows = []
        for source in ("copter", "rover", "plane"):
            for n, t, v in sets[source]:
                if n in seen or not (known(n, meta) or n in SIM_RANGES):
                    continue
                seen.add(n)
                rows.append(row(n, t, v, metas[source].get(n) if n not in meta else meta[n]))
        for n, (t, v) in OWN[vehicle].items():
            if n not in seen:
                rows.append(row(n, t, v, meta.get(n)))
        write(out_dir, vehicle, f"ArduPilot {release} metadata names with the captured types and values", rows)
    copter = metas["copter"]
    rows = [row(n, t, v, copter.get(n)) for n, t, v in sets["copter"]
            if n.startswith(COMPANION_PREFIXES) or COMPANION_SR.match(n)]
    write(out_dir, "companion", "the common libraries' identity, stream, statistics and scheduler parameters", rows)


if __name__ == "__main__":
    root = Path(__file__).resolve().parent.parent
    main(Path(sys.argv[1]), Path(sys.argv[2]), root / "src" / "gcsd" / "params" / "data")
