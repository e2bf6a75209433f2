"""Values outside the documented ranges (issue 17, item 12): stored as ArduPilot stores them, and
whatever acts on them copes. Every writable parameter of each vehicle type is set far below, then
far above its range, through PARAM_SET, while the vehicle flies: nothing fails, the vehicle keeps
reporting, and the values read back as written."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M
from vehicle_harness import Harness

from gcsd.vehicle.params.store import TYPE_RANGE

VEHICLES = ["copter", "plane", "rover", "sub", "tracker", "blimp", "companion"]
SKIP = {
    "SYSID_THISMAV",  # who the vehicle is: acts at the next start (test_swarm)
    "SYSID_MYGCS", "SYSID_ENFORCE",  # who may write: later writes from this station would be refused
}


def extreme(d, above: bool) -> float:
    """Ten spans beyond the documented range, within the C type (what a PARAM_SET can store)."""
    lo = d.min if d.min is not None else -1000.0
    hi = d.max if d.max is not None else 1000.0
    value = hi + 10 * (hi - lo + 1) if above else lo - 10 * (hi - lo + 1)
    if d.ptype in TYPE_RANGE:
        value = max(TYPE_RANGE[d.ptype][0], min(TYPE_RANGE[d.ptype][1], value))
    return float(value)


@pytest.mark.parametrize("vehicle", VEHICLES)
@pytest.mark.parametrize("above", [False, True], ids=["below", "above"])
def test_every_parameter_far_outside_its_range_is_stored_and_nothing_fails(tmp_path, vehicle, above):
    h = Harness(tmp_path, vehicle=vehicle)
    if h.node.vehicle.mode_number("GUIDED") is not None:  # blimp and companion have none
        h.mode("GUIDED")
    h.arm(force=True)
    h.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10)
    h.run(5.0)
    store = h.node.params
    written = {}
    for entry in store.entries():
        d = store.definition(entry.name)
        if d.read_only or entry.name in SKIP:
            continue
        written[entry.name] = extreme(d, above)
        h.set_param(entry.name, written[entry.name])
    mark = h.mark()
    h.run(3.0)
    assert h.node.errors.snapshot() == {}
    assert len(h.of_type("HEARTBEAT", mark)) >= 2, "the vehicle keeps reporting"
    outside = [n for n, v in written.items() if store.get(n) != pytest.approx(v, rel=1e-6, abs=1e-3)]
    assert outside == [], [(n, written[n], store.get(n)) for n in outside]
