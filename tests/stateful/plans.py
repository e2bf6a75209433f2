"""Hypothesis strategies for the stateful test: mission, fence and rally plans, parameter writes.

Plans are MISSION_ITEM_INT messages with seq 0 the home position (ArduPilot's convention). A
mission mixes take-off, waypoints near home, loiters, zero-length delays, speed changes, DO_JUMP
loops with a finite repeat count (back to any earlier item, or to an index out of the plan) and
a landing or RTL; now and then an item has a random command, frame or a NaN parameter, which the
daemon may refuse (any MISSION_ACK is an answer; what it accepted must be on disk).

Parameters come from the copter's own list (gcsd.vehicle.params.defs), minus the ones the test cannot
treat as plain values (`NOT_WRITTEN`, each with why).
"""

from __future__ import annotations

import math

from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.params.defs import parameter_set
from gcsd.vehicle.params.store import INT8, INT16, INT32, REAL32

HOME_E7 = (-353632620, 1491652370)  # the default home
MISSION, FENCE, RALLY = M.MAV_MISSION_TYPE_MISSION, M.MAV_MISSION_TYPE_FENCE, M.MAV_MISSION_TYPE_RALLY
REL = M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


def item(command: int, p=(0.0, 0.0, 0.0, 0.0), x: int = 0, y: int = 0, z: float = 0.0,
         frame: int = REL, mission_type: int = MISSION):
    return M.MAVLink_mission_item_int_message(0, 0, 0, frame, command, 0, 1, *p, x, y, z, mission_type)


def home():
    return item(M.MAV_CMD_NAV_WAYPOINT, x=HOME_E7[0], y=HOME_E7[1], z=584.0, frame=M.MAV_FRAME_GLOBAL)


near = st.tuples(st.integers(-3000, 3000), st.integers(-3000, 3000))  # within ~30 m of home
altitude = st.floats(2.0, 60.0)


@st.composite
def mission_item(draw, length: int):
    kind = draw(st.sampled_from(["wp", "wp", "takeoff", "loiter", "delay", "speed", "jump", "land", "rtl",
                                 "odd"]))
    dx, dy = draw(near)
    x, y = HOME_E7[0] + dx, HOME_E7[1] + dy
    if kind == "wp":
        return item(M.MAV_CMD_NAV_WAYPOINT, x=x, y=y, z=draw(altitude))
    if kind == "takeoff":
        return item(M.MAV_CMD_NAV_TAKEOFF, z=draw(altitude))
    if kind == "loiter":
        return item(M.MAV_CMD_NAV_LOITER_TIME, (draw(st.floats(0.0, 3.0)), 0, 0, 0), x=x, y=y, z=draw(altitude))
    if kind == "delay":
        return item(M.MAV_CMD_NAV_DELAY, (draw(st.sampled_from([0.0, 0.5, 1.0])), -1, -1, -1))
    if kind == "speed":
        return item(M.MAV_CMD_DO_CHANGE_SPEED, (1, draw(st.floats(0.5, 20.0)), -1, 0))
    if kind == "jump":  # a finite loop to an earlier item, or a target outside the plan
        target = draw(st.integers(1, length + 2))
        return item(M.MAV_CMD_DO_JUMP, (target, draw(st.integers(0, 3)), 0, 0))
    if kind == "land":
        return item(M.MAV_CMD_NAV_LAND, x=x, y=y)
    if kind == "rtl":
        return item(M.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    command = draw(st.sampled_from(sorted(M.enums["MAV_CMD"])))
    frame = draw(st.sampled_from([REL, M.MAV_FRAME_GLOBAL_INT, M.MAV_FRAME_MISSION, 200]))
    p1 = draw(st.sampled_from([0.0, 1.0, math.nan, 1e9]))
    return item(command, (p1, 0, 0, 0), x=x, y=y, z=draw(altitude), frame=frame)


@st.composite
def mission(draw):
    length = draw(st.integers(0, 14))
    return [home()] + [draw(mission_item(length)) for _ in range(length)]


@st.composite
def fence(draw):
    radius = draw(st.floats(5.0, 500.0))
    circle = item(M.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, (radius, 0, 0, 0), *HOME_E7, frame=M.MAV_FRAME_GLOBAL_INT,
                  mission_type=FENCE)
    return [circle] if draw(st.booleans()) else []


@st.composite
def rally(draw):
    points = draw(st.lists(near, max_size=4))
    return [item(M.MAV_CMD_NAV_RALLY_POINT, x=HOME_E7[0] + dx, y=HOME_E7[1] + dy, z=20.0, mission_type=RALLY)
            for dx, dy in points]


plan = st.one_of(mission().map(lambda p: (MISSION, p)), fence().map(lambda p: (FENCE, p)),
                 rally().map(lambda p: (RALLY, p)))


def instant_jump_loop():
    """[home, TAKEOFF 10, NAV_DELAY 0, DO_JUMP 2 repeat -1]: issue #17 item 6's plan."""
    return [home(), item(M.MAV_CMD_NAV_TAKEOFF, z=10.0), item(M.MAV_CMD_NAV_DELAY, (0, -1, -1, -1)),
            item(M.MAV_CMD_DO_JUMP, (2, -1, 0, 0))]


# --- parameters ------------------------------------------------------------------------------------

NOT_WRITTEN = {
    "SYSID_": "identity: the set_sysid rule writes SYSID_THISMAV; the others make the test's stations strangers",
    "MAV_SYSID": "identity, as SYSID_",
    "MAV_GCS_SYSID": "identity, as SYSID_",
    "STAT_": "counters gcsd keeps itself (the value read back changes by design)",
    "FORMAT_VERSION": "kept by gcsd",
    "SIM_SPEEDUP": "up to 1000x simulation: a CPU load the CI machine cannot carry, not a defect",
    "SIM_RATE_HZ": "as SIM_SPEEDUP",
    "SCHED_LOOP_RATE": "next start only, and it bounds message intervals",
}

DEFS = {d.name: d for d in parameter_set("copter")}
WRITTEN = sorted(n for n in DEFS if not any(n.startswith(prefix) for prefix in NOT_WRITTEN))


TYPE_RANGE = {INT8: (-128, 127), INT16: (-32768, 32767), INT32: (-1_000_000, 1_000_000),  # float32-exact
              REAL32: (-1e6, 1e6)}


def in_range(name: str):
    """A value within the parameter's metadata range (its type's range where it has none)."""
    d = DEFS[name]
    lo = d.min if d.min is not None else TYPE_RANGE[d.ptype][0]
    hi = d.max if d.max is not None else TYPE_RANGE[d.ptype][1]
    if d.ptype == REAL32:
        return st.floats(lo, hi, allow_nan=False, width=32)
    type_lo, type_hi = TYPE_RANGE[d.ptype]
    return st.integers(max(math.ceil(lo), type_lo), min(math.floor(hi), type_hi)).map(float)


def out_of_range(name: str):
    """A value outside the metadata range that its C type still holds (ArduPilot stores it)."""
    d = DEFS[name]
    type_lo, type_hi = TYPE_RANGE[d.ptype]
    values = []
    if d.max is not None and d.max + 1 <= type_hi:
        values.append(min(type_hi, d.max + max(1.0, abs(d.max))))
    if d.min is not None and d.min - 1 >= type_lo:
        values.append(max(type_lo, d.min - max(1.0, abs(d.min))))
    if d.ptype != REAL32:
        values = [float(math.floor(v)) if v > 0 else float(math.ceil(v)) for v in values]
    return st.sampled_from(values or [0.0])


has_range = [n for n in WRITTEN if DEFS[n].min is not None or DEFS[n].max is not None]

PLAN_FILES = {MISSION: "mission", FENCE: "fence", RALLY: "rally"}
