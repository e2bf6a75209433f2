"""Every configuration under sitl/ is valid (what `gcsd check-config` accepts)."""

from __future__ import annotations

from pathlib import Path

import pytest

from gcsd.config import load_config

SITL = Path(__file__).resolve().parents[2] / "sitl"


@pytest.mark.parametrize("path", sorted(SITL.glob("*.yaml")), ids=lambda p: p.name)
def test_sitl_configuration_is_valid(path):
    config = load_config(path)
    assert config.vehicle.type in path.stem or path.stem == "swarm"


def test_the_swarm_configuration_runs_twenty_copters():
    assert load_config(SITL / "swarm.yaml").vehicle.count == 20
