"""Mode tables come from pymavlink's own maps, unchanged."""

import pytest
from pymavlink import mavutil

from gcsd.vehicle.types.modes import mode_mapping


@pytest.mark.parametrize("name", ["apm", "acm", "rover", "tracker", "sub", "blimp"])
def test_mode_tables_equal_pymavlinks_maps(name):
    assert mode_mapping(name) == getattr(mavutil, f"mode_mapping_{name}")
