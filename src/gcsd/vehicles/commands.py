"""Commands whose meaning differs per vehicle type: `handler(node, request) -> MAV_RESULT`.

A vehicle type lists the ones it supports in `VehicleType.commands`; a vehicle that lists
none answers UNSUPPORTED (a sub or a rover cannot take off).

- takeoff_in_guided (copter, blimp): NAV_TAKEOFF param7 = altitude above home; needs GUIDED,
  armed, on the ground (else FAILED), as ArduCopter's do_user_takeoff.
- takeoff_mode (plane): NAV_TAKEOFF switches to TAKEOFF mode; param7 > 0 sets its altitude.
- land_start (plane): DO_LAND_START jumps the mission to its DO_LAND_START marker and flies on.
- motor_test (copter): DO_MOTOR_TEST param1 motor, param3 throttle %, param4 seconds;
  disarmed only (DENIED armed).
- set_reverse (rover): DO_SET_REVERSE param1 1 drives backwards.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as M

ACCEPTED, DENIED, FAILED = M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_DENIED, M.MAV_RESULT_FAILED


def takeoff_in_guided(node, req) -> int:
    alt = req.z
    if not math.isfinite(alt) or alt <= 0:
        alt = node.sim.settings.takeoff_alt_m
    return ACCEPTED if node.sim.takeoff(alt) else FAILED


def takeoff_mode(node, req) -> int:
    if math.isfinite(req.z) and req.z > 0:
        node.sim.set_takeoff_alt(req.z)
    return ACCEPTED if node.sim.set_mode("TAKEOFF") else FAILED


def land_start(node, req) -> int:
    items = node.mission.mission.stored()
    for seq, item in enumerate(items):
        if item.command == M.MAV_CMD_DO_LAND_START:
            node.mission.mission.set_current(seq)
            return ACCEPTED if node.sim.start_mission(seq) else FAILED
    return FAILED


def motor_test(node, req) -> int:
    if node.state.armed:
        return DENIED
    motor = int(req.param1)
    if not 1 <= motor <= 8 or not 0 <= req.param3 <= 100:
        return FAILED
    node.sim.motor_test(motor, req.param3, max(0.0, min(req.param4, 600.0)))
    return ACCEPTED


def set_reverse(node, req) -> int:
    node.sim.reversed = req.param1 >= 1
    return ACCEPTED
