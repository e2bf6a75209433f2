"""Fuzz: every command and every message id of the dialect, with zeros, NaN and seeded wild values,
and random plans, against the real daemon (`gcsd run`, a subprocess) for copter, plane, rover, sub.

SPEC.md "Bad input": nothing a peer sends stops the daemon. The daemon is its own process, so an
exception that escapes anywhere is a process exit, which fails the test naming the chunk that was
in flight. Frames go out back to back in chunks (one command with all its variants, or one message
id with its random payloads); after each chunk a TIMESYNC with a ts1 of its own must come back
(`FuzzedDaemon.barrier`). Each test then lets the simulation and telemetry run a while on whatever
state the fuzz left (streams asked at 10 Hz), and ends with the daemon still running, a parameter
read by name answered, HEARTBEATs arriving (at the default interval again), and no exception
logged at all (a command handler's `command_failed` or an error boundary's `component_failed`
keeps the daemon up, but is a defect all the same).

- on the ground: every command, then every message id;
- in flight: GUIDED, armed, taking off, then the same again (guided targets, overrides...);
- plans: random missions, fences and rally points (half with finite extremes only, so some are
  kept), each accepted mission flown in AUTO;
- parameters: every parameter (from the vehicle's own list) set to wild values in flight, the
  vehicle flown on what was kept, then the daemon restarted on the persisted values.

Bounded for CI (about 200 commands x 2 encodings x 4 sets, 300 ids x 4 payloads, 12 plans per
type): GCSD_FUZZ_SEED changes the seed, GCSD_FUZZ_ROUNDS (default 2) multiplies the wild sets,
payloads and plans, for longer hunts by hand.
"""

from __future__ import annotations

import os
import random

import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as M

from .daemon import VEHICLE, FuzzedDaemon
from .frames import Chunk, command_chunks, message_chunks, param_chunks, random_plan

SEED = int(os.environ.get("GCSD_FUZZ_SEED", "20261125"))
ROUNDS = int(os.environ.get("GCSD_FUZZ_ROUNDS", "2"))
VEHICLES = ["copter", "plane", "rover", "sub"]
MAV_TYPES = {"copter": M.MAV_TYPE_QUADROTOR, "plane": M.MAV_TYPE_FIXED_WING, "rover": M.MAV_TYPE_GROUND_ROVER,
             "sub": M.MAV_TYPE_SUBMARINE}
SOAK_S = 2.0
HOME_E7 = (-353632620, 1491652370)  # the default home


@pytest.fixture
def fuzzed(tmp_path):
    started: list[FuzzedDaemon] = []

    def start(vehicle: str, extra_yaml: str = "", vehicle_keys: str = "") -> FuzzedDaemon:
        (tmp_path / vehicle).mkdir()
        d = FuzzedDaemon(tmp_path / vehicle, vehicle, extra_yaml, vehicle_keys)
        started.append(d)
        d.start()
        # every stream at 10 Hz: the telemetry producers run often on whatever state the fuzz leaves
        d.send_msg(M.MAVLink_request_data_stream_message(*VEHICLE, M.MAV_DATA_STREAM_ALL, 10, 1))
        return d

    yield start
    for d in started:
        d.stop()


def run_chunks(d: FuzzedDaemon, chunks, what: str) -> int:
    """Send every chunk back to back, each followed by a barrier; fail naming the chunk that killed it."""
    sent = 0
    for n, chunk in enumerate(chunks):
        assert isinstance(chunk, Chunk)
        for frame in chunk.frames:
            d.send(frame)
        sent += len(chunk.frames)
        d.read(0)  # keep our receive buffer drained (telemetry and ACKs)
        if not d.barrier():
            fail(d, f"{what}: after chunk {n} ({chunk.name}, {len(chunk.frames)} frames)")
    return sent


def fail(d: FuzzedDaemon, where: str) -> None:
    state = f"exited with code {d.proc.returncode}" if not d.alive() else "stopped answering"
    pytest.fail(f"the daemon {state}, {where}\n--- log tail ---\n{d.log_tail()}")


def assert_still_serving(d: FuzzedDaemon, what: str) -> None:
    d.soak(SOAK_S)
    if not d.alive():
        fail(d, f"{what}: while the simulation ran on for {SOAK_S} s after the last chunk")
    assert d.param_read_answered(), f"{what}: PARAM_REQUEST_READ not answered\n{d.log_tail()}"
    # the fuzz may have set any HEARTBEAT interval (SET_MESSAGE_INTERVAL): back to the default, as a
    # ground station would, and the heartbeat must come
    assert d.command(M.MAV_CMD_SET_MESSAGE_INTERVAL, M.MAVLINK_MSG_ID_HEARTBEAT, 0) == M.MAV_RESULT_ACCEPTED
    assert d.heartbeat_arrives(), f"{what}: no HEARTBEAT any more"
    # an exception the daemon caught and logged (a command handler's FAILED, an error boundary around
    # a producer or a handler) is a defect all the same: what a peer sends must never raise
    raised = [r for r in d.log_records() if "exception" in r]
    summary = sorted({f"{r.get('component', r.get('event'))}: {r['exception'].splitlines()[-1]}" for r in raised})
    assert raised == [], f"{what}: {len(raised)} exceptions logged: {summary}\nfirst: {raised[0]['exception']}"

def mode(vehicle: str, name: str) -> int:
    return mavutil.mode_mapping_byname(MAV_TYPES[vehicle])[name]


def fly(d: FuzzedDaemon, vehicle: str) -> None:
    """GUIDED, armed (forced), taking off: best effort, the fuzz goes on whatever the vehicle says."""
    d.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode(vehicle, "GUIDED"))
    d.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, 21196)
    d.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 10)
    d.soak(0.5)


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_every_command_and_message_id_on_the_ground_leaves_the_daemon_serving(fuzzed, vehicle):
    d = fuzzed(vehicle)
    sent = run_chunks(d, command_chunks(VEHICLE, SEED, ROUNDS), f"{vehicle} commands")
    assert sent >= 200 * 2 * (2 + ROUNDS)
    sent = run_chunks(d, message_chunks(VEHICLE, SEED, 2 * ROUNDS), f"{vehicle} messages")
    assert sent == len(M.mavlink_map) * 2 * ROUNDS
    assert_still_serving(d, vehicle)


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_every_command_and_message_id_in_guided_flight_leaves_the_daemon_serving(fuzzed, vehicle):
    d = fuzzed(vehicle)
    fly(d, vehicle)
    run_chunks(d, message_chunks(VEHICLE, SEED + 1, 2 * ROUNDS), f"{vehicle} messages in flight")
    fly(d, vehicle)
    run_chunks(d, command_chunks(VEHICLE, SEED + 1, ROUNDS), f"{vehicle} commands in flight")
    assert_still_serving(d, vehicle)


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_random_plans_uploaded_and_flown_leave_the_daemon_serving(fuzzed, vehicle):
    d = fuzzed(vehicle)
    rng = random.Random(SEED + 2)
    results = []
    for n in range(6 * ROUNDS):
        for mission_type in (M.MAV_MISSION_TYPE_FENCE, M.MAV_MISSION_TYPE_RALLY, M.MAV_MISSION_TYPE_MISSION):
            plan = random_plan(rng, mission_type, HOME_E7, rng.randint(1, 6))
            result = d.upload(mission_type, plan)
            if result is None:
                fail(d, f"{vehicle}: plan {n} of type {mission_type} not acknowledged: {plan}")
            results.append(result)
        if results[-1] == M.MAV_MISSION_ACCEPTED:  # a mission of extreme values was kept: fly it
            fly(d, vehicle)
            d.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, mode(vehicle, "AUTO"))
            d.command(M.MAV_CMD_MISSION_START)
            d.soak(1.0)
            if not d.barrier():
                fail(d, f"{vehicle}: flying random mission {n}")
    assert M.MAV_MISSION_ACCEPTED in results and len(set(results)) > 1, results  # both outcomes exercised
    assert_still_serving(d, vehicle)


@pytest.mark.parametrize("vehicle", VEHICLES)
def test_every_parameter_set_to_wild_values_in_flight_and_after_a_restart_leaves_the_daemon_serving(fuzzed,
                                                                                                    vehicle):
    d = fuzzed(vehicle)
    names = d.param_names()
    fly(d, vehicle)
    run_chunks(d, param_chunks(names, VEHICLE, SEED + 3, ROUNDS), f"{vehicle} parameters")
    fly(d, vehicle)  # the simulation now runs on whatever values were accepted
    assert_still_serving(d, vehicle)
    # the values that were kept are persisted: the daemon must start on them (a clean stop first)
    assert d.restart() == 0, d.log_tail()
    fly(d, vehicle)
    assert_still_serving(d, f"{vehicle} after a restart")


PAYLOAD_VEHICLE_KEYS = ", camera: true, gimbal: true"
CAMERA = (1, 100)


@pytest.mark.parametrize("vehicle", ["copter", "plane"])
def test_camera_gimbal_and_can_get_every_command_and_message_and_the_daemon_serves(fuzzed, vehicle, tmp_path):
    """With the payload on (camera, gimbal, a virtual CAN bus with simulated nodes): every command to the
    autopilot and to the camera component, every message id (CAN_FRAME, CANFD_FRAME, CAN_FILTER_MODIFY,
    GIMBAL_MANAGER_SET_* among them) after a CAN_FORWARD, in flight, and every MNT1_ parameter wild."""
    can = f"can:\n  buses:\n    - {{interface: virtual, channel: fuzz-{tmp_path.name}, nodes: [gps, battery]}}\n"
    d = fuzzed(vehicle, can, PAYLOAD_VEHICLE_KEYS)
    assert d.command(M.MAV_CMD_CAN_FORWARD, 1) == M.MAV_RESULT_ACCEPTED
    fly(d, vehicle)
    run_chunks(d, command_chunks(CAMERA, SEED + 4, ROUNDS), f"{vehicle} commands to the camera")
    run_chunks(d, command_chunks(VEHICLE, SEED + 5, ROUNDS), f"{vehicle} commands with a payload")
    assert d.command(M.MAV_CMD_CAN_FORWARD, 1) == M.MAV_RESULT_ACCEPTED
    run_chunks(d, message_chunks(VEHICLE, SEED + 6, 2 * ROUNDS), f"{vehicle} messages with a payload")
    names = [n for n in d.param_names() if n.startswith("MNT1_")]
    assert len(names) == 19, names
    run_chunks(d, param_chunks(names, VEHICLE, SEED + 7, ROUNDS), f"{vehicle} MNT1_ parameters")
    fly(d, vehicle)
    assert_still_serving(d, f"{vehicle} with a payload")
