"""Parameter definitions: ArduPilot's parameter set of each vehicle type, as package data.

`params/data/<set>.tsv` holds, in ArduPilot's index order, every parameter of a vehicle type:
name, MAV_PARAM_TYPE, default, range, flags (R: ArduPilot wants a reboot, O: read-only), units
and ArduPilot's display name. Copter, plane and rover are ArduPilot SITL's own lists mapped to
4.6; the other types are the closest data that can be justified (tools/param_data.py builds the
files once and says how; docs/parameters.md lists which parameters act).

A file is parsed once per process (`parameter_set`, cached; ~1 000 definitions in a few ms) and
its definitions are shared by every vehicle of that type. `vehicle_defs` then replaces the few
defaults that come from the configuration: SYSID_THISMAV, SYSID_MYGCS, SYSID_ENFORCE (`gcs`
section), SRn_* (channel n's `streams`; a channel beyond the set's SR groups gets its own SRn_
group, shaped like SR0_), SIM_SPEEDUP (`vehicle.speedup`).

`reboot` (gcsd sends "<NAME> takes effect at the next start" after a write) is set only where
gcsd applies a value at the next start (SYSID_THISMAV, SCHED_LOOP_RATE); the metadata's R flag
is kept in the data for reference: gcsd applies stream rates at once, for instance.
"""

from __future__ import annotations

import dataclasses
from functools import cache
from pathlib import Path

from gcsd.vehicle.params.store import INT8, INT16, INT32, REAL32, ParamDef, as_float
from gcsd.wire.streams import PARAM_SUFFIX, STREAM_NAMES

DATA_DIR = Path(__file__).resolve().parent / "data"
TYPES = {"INT8": INT8, "INT16": INT16, "INT32": INT32, "REAL32": REAL32}
NEXT_START = frozenset({"SYSID_THISMAV", "SCHED_LOOP_RATE"})


def _number(text: str) -> float | None:
    return None if text == "" else float(text)


@cache
def parameter_set(name: str) -> tuple[ParamDef, ...]:
    """The definitions of `params/data/<name>.tsv`, in ArduPilot's order."""
    defs = []
    for line in (DATA_DIR / f"{name}.tsv").read_text().splitlines():
        if not line or line.startswith("#"):
            continue
        pname, ptype, default, lo, hi, flags, units, display = line.split("\t")
        code = TYPES[ptype]
        value = float(default) if code == REAL32 else int(float(default))
        low, high = _number(lo), _number(hi)
        if code == REAL32:  # a ground station sends float32: 0.2 arrives as 0.2000000030, in range
            low, high = (None if x is None else as_float(x) for x in (low, high))
        defs.append(ParamDef(pname, code, value, low, high, units, display,
                             read_only="O" in flags, reboot=pname in NEXT_START))
    return tuple(defs)


def stream_param(name: str) -> tuple[int, str] | None:
    """SRn_<suffix> -> (n, stream name); anything else -> None."""
    if not name.startswith("SR") or "_" not in name:
        return None
    head, suffix = name.split("_", 1)
    if not head[2:].isdigit():
        return None
    for stream in STREAM_NAMES:
        if PARAM_SUFFIX[stream] == suffix:
            return int(head[2:]), stream
    return None


def vehicle_defs(set_name: str, sysid: int, gcs_sysid: int, enforce: bool,
                 channel_rates: list[dict[str, float]], speedup: float = 1.0) -> list[ParamDef]:
    """A vehicle's definitions: the set, with the defaults the configuration decides."""
    fixed: dict[str, float] = {"SYSID_THISMAV": sysid, "SYSID_MYGCS": gcs_sysid, "SYSID_ENFORCE": int(enforce),
                               "SIM_SPEEDUP": speedup}
    for index, rates in enumerate(channel_rates):
        for stream in STREAM_NAMES:
            fixed[f"SR{index}_{PARAM_SUFFIX[stream]}"] = int(rates[stream])
    out: list[ParamDef] = []
    shape: dict[str, ParamDef] = {}  # stream -> the SR0_ definition, for channels the set lacks
    last_sr = -1
    for d in parameter_set(set_name):
        sr = stream_param(d.name)
        if sr is not None:
            last_sr = len(out)
            if sr[0] == 0:
                shape[sr[1]] = d
        if d.name in fixed and fixed[d.name] != d.default:
            d = _with_default(d, fixed[d.name])
        out.append(d)
    have = {d.name for d in out}
    extra = []
    for index, rates in enumerate(channel_rates):
        for stream in STREAM_NAMES:
            name = f"SR{index}_{PARAM_SUFFIX[stream]}"
            if name not in have and stream in shape:
                extra.append(_with_default(dataclasses.replace(shape[stream], name=name), int(rates[stream])))
    if extra:
        out[last_sr + 1:last_sr + 1] = extra
    return out


def _with_default(d: ParamDef, value: float) -> ParamDef:
    """d with a configured default; its range widened to hold it (the configuration was validated)."""
    lo = d.min if d.min is None else min(d.min, value)
    hi = d.max if d.max is None else max(d.max, value)
    return dataclasses.replace(d, default=value, min=lo, max=hi)
