"""The edge check of command parameters (services/command_rules.py): a pure function of the values."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.services.command_rules import RULES, STRICT, check, rule

NAN, INF = math.nan, math.inf
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
LAT, LON = -353632620, 1491652370
DENIED, FAILED = M.MAV_RESULT_DENIED, M.MAV_RESULT_FAILED


def values(*params, x=0, y=0, z=0.0):
    p = list(params) + [0.0] * (4 - len(params))
    return (*p, x, y, z)


def test_parameters_a_command_does_not_use_are_ignored_and_reach_the_handler_as_zero():
    assert check(rule("1"), values(1, NAN, INF, -INF, x=NAN, y=INF, z=NAN), REL) == values(1)


@pytest.mark.parametrize("bad", [NAN, INF, -INF])
def test_a_used_parameter_that_is_not_a_finite_number_is_denied(bad):
    assert check(rule("12"), values(1, bad), REL) == DENIED


def test_nan_passes_where_it_has_a_meaning_but_infinity_never_does():
    out = check(rule("14", nan_ok="4"), values(1, 0, 0, NAN), REL)
    assert out[0] == 1 and math.isnan(out[3])
    assert check(rule("14", nan_ok="4"), values(1, 0, 0, INF), REL) == DENIED


def test_limits_bound_the_absolute_value():
    assert check(rule("1", limits={1: 100.0}), values(-100.0), REL) == values(-100.0)
    assert check(rule("1", limits={1: 100.0}), values(100.5), REL) == DENIED


def test_a_command_nobody_described_uses_all_seven_parameters():
    assert check(STRICT, values(1, 2, 3, 4, x=5, y=6, z=7), REL) == values(1, 2, 3, 4, x=5, y=6, z=7)
    assert check(STRICT, values(z=NAN), REL) == DENIED
    assert 12345 not in RULES


@pytest.mark.parametrize(("x", "y", "z", "frame", "result"), [
    (LAT, LON, 10.0, REL, None),
    (0, 0, 10.0, REL, None),  # "here" / "none"
    (LAT, LON, NAN, REL, DENIED),  # ArduPilot's location_from_command_t
    (LAT, LON, 83_000.5, REL, DENIED),
    (LAT, LON, 10.0, M.MAV_FRAME_LOCAL_NED, DENIED),
    (900_000_001, LON, 10.0, REL, DENIED),  # check_latlng
    (LAT, NAN, 10.0, REL, DENIED),
    (LAT, INF, 10.0, REL, DENIED),
])
def test_a_location_is_checked_as_a_whole(x, y, z, frame, result):
    out = check(rule("1", location=True), values(1, x=x, y=y, z=z), frame)
    assert out == (values(1, x=x, y=y, z=z) if result is None else result)


def test_set_home_refuses_a_bad_position_with_failed_and_ignores_it_when_told_to_use_here():
    set_home = RULES[M.MAV_CMD_DO_SET_HOME]
    assert check(set_home, values(0, x=950_000_000, y=LON, z=10.0), REL) == FAILED
    assert check(set_home, values(0, x=LAT, y=LON, z=NAN), REL) == DENIED
    assert check(set_home, values(1, x=950_000_000, y=INF, z=NAN), REL) == values(1)  # param1 1: here


def test_arm_disarm_gets_nan_through_to_answer_unsupported_as_arducopter():
    out = check(RULES[M.MAV_CMD_COMPONENT_ARM_DISARM], values(NAN, NAN), REL)
    assert math.isnan(out[0]) and math.isnan(out[1])
