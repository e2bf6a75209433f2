"""A Python robot that ground stations drive through gcsd: the embedding API (gcsd.embed) in use.

The robot is a differential-drive rover with its own model (not gcsd's simulation): it turns in
place towards its goal, then drives straight at up to `max_speed_ms`, and stops inside the
waypoint radius gcsd gives it. gcsd supplies everything MAVLink: heartbeats and telemetry from the
robot's state, parameters, missions, modes (GUIDED, AUTO, RTL, HOLD...), commands and pre-arm
checks; the robot adds one check of its own (its motor controller must be connected).

    python sitl/embed_robot.py                  # UDP server on 0.0.0.0:14551, state in ./robot-state
    python sitl/embed_robot.py --port 14560 --state-dir /tmp/robot

Then, e.g. with MAVProxy (`mavproxy.py --master=udpout:127.0.0.1:14551`): `mode GUIDED`,
`arm throttle`, `guided -35.3631 149.1653 0`; or upload a mission and `mode AUTO`.
"""

from __future__ import annotations

import argparse
import math
import sys

import yaml

from gcsd.config import parse_config
from gcsd.embed import run
from gcsd.vehicle.sim import Kind, Landed, Limits, Setpoint, VehicleState
from gcsd.vehicle.sim.geo import ne_m, offset, wrap_180


class DiffDriveRobot:
    """The robot's own kinematics and motor state; gcsd reads it, and tells it where to go."""

    def __init__(self, max_speed_ms: float = 1.5, turn_rate_dps: float = 90.0) -> None:
        self.max_speed_ms = max_speed_ms
        self.turn_rate_dps = turn_rate_dps
        self.motors_connected = True
        self.odometer_m = 0.0
        self.last_setpoint: Setpoint | None = None

    def prearm_failures(self) -> list[str]:
        return [] if self.motors_connected else ["Robot: motor controller not connected"]

    def update(self, state: VehicleState, setpoint: Setpoint, limits: Limits, dt_s: float) -> None:
        self.last_setpoint = setpoint
        speed, turn = 0.0, 0.0
        if state.armed and setpoint.kind in (Kind.GOTO, Kind.HOLD, Kind.LAND):
            north, east = ne_m(state.lat, state.lon, setpoint.lat, setpoint.lon)
            distance = math.hypot(north, east)
            if distance > limits.wp_radius_m * 0.5:
                error = wrap_180(math.degrees(math.atan2(east, north)) - math.degrees(state.yaw_rad))
                turn = max(-self.turn_rate_dps * dt_s, min(self.turn_rate_dps * dt_s, error))
                if abs(error) < 20.0:  # facing the goal: drive
                    cruise = setpoint.speed_ms or limits.cruise_speed_ms
                    speed = min(cruise, self.max_speed_ms, distance / max(dt_s, 1e-3))
        state.yaw_rad = math.radians((math.degrees(state.yaw_rad) + turn) % 360.0)
        state.vn_ms = speed * math.cos(state.yaw_rad)
        state.ve_ms = speed * math.sin(state.yaw_rad)
        state.lat, state.lon = offset(state.lat, state.lon, state.vn_ms * dt_s, state.ve_ms * dt_s)
        state.airspeed_ms = speed
        state.landed = Landed.ON_GROUND
        state.throttle_pct = int(100 * speed / self.max_speed_ms) if state.armed else 0
        state.current_a = 0.3 + 4.0 * speed / self.max_speed_ms
        state.consumed_mah += state.current_a * dt_s / 3.6
        self.odometer_m += speed * dt_s


def config(port: int, state_dir: str, host: str = "0.0.0.0"):
    return parse_config(yaml.safe_dump({
        "vehicle": {"type": "rover"},
        "state_dir": state_dir,
        "channels": [{"name": "gcs", "type": "udp-server", "address": f"{host}:{port}"}],
    }), "embed_robot")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--port", type=int, default=14551)
    p.add_argument("--state-dir", default="./robot-state")
    a = p.parse_args(argv)
    return run(config(a.port, a.state_dir), DiffDriveRobot())


if __name__ == "__main__":
    sys.exit(main())
