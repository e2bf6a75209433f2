"""Vehicle types as data: modes from pymavlink's maps, a behaviour per mode, parameters that each
change the vehicle's settings (or are read by the fence, RTL, failsafe and stick code named here)."""

from __future__ import annotations

import pytest
from pymavlink import mavutil

from gcsd.vehicle.params import parameter_set
from gcsd.vehicle.types import VEHICLE_TYPES

READ_ELSEWHERE = {  # parameter -> where it acts, when not through Settings
    "FENCE_ENABLE": "autopilot.fence", "FENCE_TYPE": "autopilot.fence", "FENCE_ALT_MAX": "autopilot.fence",
    "FENCE_ALT_MIN": "autopilot.fence", "FENCE_RADIUS": "autopilot.fence", "FENCE_MARGIN": "vehicles.prearm",
    "RALLY_INCL_HOME": "autopilot.rtl", "RALLY_LIMIT_KM": "autopilot.rtl",
    "BATT_LOW_VOLT": "autopilot.failsafe", "BATT_LOW_MAH": "autopilot.failsafe",
    "BATT_CRT_VOLT": "autopilot.failsafe", "BATT_CRT_MAH": "autopilot.failsafe",
    "RC_OVERRIDE_TIME": "autopilot.actions", "ANGLE_MAX": "vehicles.prearm and Limits",
}
MAPS = {"copter": mavutil.mode_mapping_acm, "plane": mavutil.mode_mapping_apm, "rover": mavutil.mode_mapping_rover,
        "sub": mavutil.mode_mapping_sub, "tracker": mavutil.mode_mapping_tracker, "blimp": mavutil.mode_mapping_blimp}


@pytest.mark.parametrize("name", sorted(MAPS))
def test_modes_are_pymavlinks_and_each_has_a_behaviour(name):
    v = VEHICLE_TYPES[name]
    assert v.modes == MAPS[name]
    assert set(v.behaviours) == set(v.modes)
    assert mavutil.mode_mapping_bynumber(v.mav_type) == v.modes  # what ground stations decode


def _candidates(d):
    """Other values in range: the limits and neighbours of the default."""
    values = {d.min, d.max, d.default + 1, d.default - 1, d.default * 2 + 1}
    return [x for x in values if x is not None and x != d.default
            and (d.min is None or x >= d.min) and (d.max is None or x <= d.max)]


@pytest.mark.parametrize("name", sorted(n for n in VEHICLE_TYPES if VEHICLE_TYPES[n].params))
def test_every_vehicle_parameter_changes_the_settings_or_is_read_elsewhere(name):
    v = VEHICLE_TYPES[name]
    every = parameter_set(v.parameter_set())
    defaults = {d.name: d.default for d in every}
    base = v.settings(defaults.__getitem__)
    inert = []
    by_name = {d.name: d for d in every}
    assert set(v.params) <= set(by_name)  # ArduPilot's names for the type: nothing invented
    for d in (by_name[n] for n in v.params):
        moves = any(v.settings(dict(defaults, **{d.name: x}).__getitem__) != base for x in _candidates(d))
        if not moves and d.name not in READ_ELSEWHERE:
            inert.append(d.name)
    assert inert == []


def test_stream_rates_recorded_for_ardupilot_match_the_reference():
    rates = {n: tuple(VEHICLE_TYPES[n].ardupilot_stream_rates.values()) for n in MAPS}
    assert rates["copter"] == rates["blimp"] == (0,) * 10
    assert rates["plane"] == (1, 1, 1, 1, 1, 1, 1, 1, 10, 5)
    assert rates["rover"] == rates["tracker"] == (1, 1, 1, 1, 1, 1, 1, 1, 10, 0)
    assert rates["sub"] == (2, 2, 2, 0, 3, 10, 10, 3, 0, 0)
