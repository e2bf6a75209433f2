"""The typed parameter store: C-cast values, integer rounding, ranges, read-only, listeners."""

import math
import struct

import pytest

from gcsd.vehicle.params import INT8, INT16, INT32, REAL32, ParamDef, ParamStore, SetResult, as_float, to_type
from gcsd.vehicle.params.parmfile import format_parm, format_real32, parse_parm


def store():
    return ParamStore([
        ParamDef("B_INT8", INT8, 1, -100, 100),
        ParamDef("A_INT16", INT16, 1500, 800, 2200),
        ParamDef("C_INT32", INT32, 0),
        ParamDef("D_REAL", REAL32, 0.1),
        ParamDef("E_RO", INT16, 7, read_only=True),
    ])


def test_parameters_are_indexed_in_definition_order():
    """ArduPilot's index order is the order of the definitions (params/data/<type>.tsv)."""
    s = store()
    assert [e.name for e in s.entries()] == ["B_INT8", "A_INT16", "C_INT32", "D_REAL", "E_RO"]
    assert s.index_of("C_INT32") == 2 and s.entry(2).name == "C_INT32"


@pytest.mark.parametrize("ptype, value, expected", [
    (INT8, 3.999, 4),          # nudged by 0.01 then truncated, as AP_Param::set_float
    (INT8, 3.98, 3),
    (INT8, -3.999, -4),
    (INT8, 1000.0, 127),       # clamped to the type
    (INT16, -40000.0, -32768),
    (INT32, 2.0**40, 2**31 - 1),
    (REAL32, 0.1, as_float(0.1)),
])
def test_values_take_their_c_type(ptype, value, expected):
    assert to_type(ptype, value) == expected


def test_set_changes_value_and_reports_unchanged_second_time():
    s = store()
    assert s.set("A_INT16", 1600.0) is SetResult.CHANGED
    assert s.set("A_INT16", 1600.2) is SetResult.UNCHANGED
    assert s.get("A_INT16") == 1600


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_nan_and_infinity_change_nothing(value):
    s = store()
    assert s.set("A_INT16", value) is SetResult.INVALID
    assert s.get("A_INT16") == 1500


def test_unknown_name_is_reported_unknown():
    assert store().set("NOPE", 1.0) is SetResult.UNKNOWN


def test_read_only_refuses_ground_station_writes_but_not_our_own():
    s = store()
    assert s.set("E_RO", 8.0) is SetResult.READ_ONLY
    assert s.set("E_RO", 8.0, force=True) is SetResult.CHANGED


def test_values_outside_the_documented_range_are_stored_and_clamped_where_they_act():
    """As ArduPilot's GCS_Param.cpp: only NaN and infinity are refused; the range is advice."""
    s = store()
    assert s.set("A_INT16", 2500.0) is SetResult.CHANGED
    assert s.get("A_INT16") == 2500
    assert s.clamped("A_INT16") == s.definition("A_INT16").max
    assert s.set("A_INT16", 1500.0) is SetResult.CHANGED
    assert s.clamped("A_INT16") == 1500, "within the range: the value itself"


def test_our_own_writes_are_held_to_the_c_type():
    s = store()
    assert s.set("A_INT16", 2500.0, force=True) is SetResult.CHANGED
    assert s.get("A_INT16") == 2500
    assert s.set("B_INT8", 1000.0, force=True) is SetResult.CHANGED
    assert s.get("B_INT8") == 127


def test_listeners_run_after_a_change_only():
    s = store()
    seen = []
    s.on_change("A_INT16", lambda name, v: seen.append((name, v)))
    s.set("A_INT16", 1600.0)
    s.set("A_INT16", 1600.0)
    assert seen == [("A_INT16", 1600)]


def test_changed_from_default_lists_what_to_save():
    s = store()
    s.set("D_REAL", 0.5)
    assert [e.name for e in s.changed_from_default()] == ["D_REAL"]


def test_parm_round_trip_and_bad_lines_are_reported_with_numbers():
    s = store()
    s.set("A_INT16", 1234.0)
    s.set("D_REAL", 0.25)
    text = format_parm(s.changed_from_default()) + "GARBAGE LINE HERE\nB_INT8,5\n# comment\nC_INT32 nan\n"
    values, problems = parse_parm(text)
    assert values == {"A_INT16": 1234.0, "D_REAL": 0.25, "B_INT8": 5.0}
    assert [(p.line, p.reason) for p in problems] == [(3, "expected NAME VALUE"), (6, "C_INT32: nan is not a finite number")]


@pytest.mark.parametrize("value", [0.35000002, 0.1, 1e-45, 3.4028235e38, -2.7182817, 123456.79, 1 / 3, 0.0])
def test_real32_values_survive_a_write_and_read_bit_exact(value):
    s = ParamStore([ParamDef("D_REAL", REAL32, 7.0)])
    s.set("D_REAL", value)
    text = format_parm(s.changed_from_default())
    values, problems = parse_parm(text)
    assert problems == []
    assert struct.pack("<f", values["D_REAL"]) == struct.pack("<f", s.get("D_REAL"))


def test_real32_is_written_with_the_fewest_digits_that_read_back_exactly():
    assert format_real32(as_float(0.35000002)) == "0.35000002"  # "%.7g" wrote 0.35: another float32
    assert format_real32(as_float(0.1)) == "0.1"
    assert format_real32(as_float(0.35)) == "0.35"


def test_a_real32_value_beyond_the_float32_range_is_out_of_range_not_an_overflow():
    s = ParamStore([ParamDef("D_REAL", REAL32, 7.0)])
    assert s.set("D_REAL", 1e39) is SetResult.OUT_OF_RANGE
    assert s.set("D_REAL", -1e39) is SetResult.OUT_OF_RANGE
    assert s.get("D_REAL") == 7.0


def test_duplicate_names_are_a_definition_error():
    with pytest.raises(ValueError):
        ParamStore([ParamDef("X", INT8, 0), ParamDef("X", INT8, 1)])
