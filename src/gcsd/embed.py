"""Embedding gcsd: a Python program supplies the vehicle; gcsd is its MAVLink side.

gcsd's autopilot (modes, guided targets, missions, RTL, failsafes, pre-arm checks, commands)
normally drives the built-in simulation. An embedding program replaces the simulation with its
own *backend*: an object with one method,

    update(state, setpoint, limits, dt_s) -> None

called SIM_RATE_HZ times a real second (25 by default) with `dt_s` the time since the last call
(real seconds x SIM_SPEEDUP, cut into steps of at most 0.1 s). It must

- act on `setpoint` (gcsd.vehicle.sim.Setpoint), what the autopilot wants now: `kind` IDLE (stay on the
  ground), HOLD / GOTO (lat, lon, alt_m above mean sea level, speed_ms, yaw_deg), TAKEOFF (climb to
  alt_m), LAND (at lat/lon), VELOCITY (north, east, down m/s), MANUAL (sticks -1..1), POINT / SCAN
  (an antenna tracker); `limits` (gcsd.vehicle.sim.Limits) are the vehicle type's speeds and radii from its
  parameters;
- write where the vehicle is into `state` (gcsd.vehicle.sim.VehicleState): lat, lon, alt_amsl_m, roll_rad,
  pitch_rad, yaw_rad, vn_ms/ve_ms/vd_ms, airspeed_ms, throttle_pct, landed (gcsd.vehicle.sim.Landed),
  gps_fix_type/satellites/hdop, consumed_mah/current_a (and anything else it knows). Every
  telemetry message is built from this state. `state.armed` and `state.mode` belong to gcsd:
  read them; change `mode` only to report a mode change the vehicle made by itself.

Optionally it may define `prearm_failures() -> list[str]`: reasons it cannot arm now, reported as
"PreArm: ..." like gcsd's own checks.

    import asyncio
    from gcsd.config import load_config
    from gcsd.embed import serve

    asyncio.run(serve(load_config("robot.yaml"), MyRobot(), stop=asyncio.Event()))

or `run(config, backend)`, which also handles SIGINT/SIGTERM and returns an exit code. For a
swarm (`vehicle.count` > 1) pass a factory `backend(index)` returning one backend per vehicle.
A complete example: sitl/embed_robot.py.
"""

from __future__ import annotations

import asyncio
import signal
from collections.abc import Callable
from typing import Protocol, runtime_checkable

from gcsd.config import Config
from gcsd.daemon import statelock
from gcsd.daemon.daemon import Daemon
from gcsd.vehicle.sim import Limits, Setpoint, VehicleState


@runtime_checkable
class VehicleBackend(Protocol):
    def update(self, state: VehicleState, setpoint: Setpoint, limits: Limits, dt_s: float) -> None: ...


Backends = VehicleBackend | Callable[[int], VehicleBackend]


def _factory(backend: Backends) -> Callable[[int], VehicleBackend]:
    if isinstance(backend, VehicleBackend):
        return lambda index: backend if index == 0 else _one_only(index)
    return backend


def _one_only(index: int):
    raise ValueError("a swarm (vehicle.count > 1) needs a backend factory: backend(index) -> VehicleBackend")


def build(config: Config, backend: Backends) -> Daemon:
    """The Daemon (channels, router, vehicle nodes) with `backend` in place of the simulation."""
    return Daemon(config, backend=_factory(backend))


async def serve(config: Config, backend: Backends, stop: asyncio.Event,
                started: Callable[[Daemon], None] | None = None) -> None:
    """Serve until `stop` is set; `started(gcs)` is called once it is ready, every server channel
    bound and every client channel tried (the Daemon then gives the real ports:
    `gcs.channels[i].local_address`)."""
    config.state_dir.mkdir(parents=True, exist_ok=True)
    lock = statelock.acquire(config.state_dir)  # one daemon per state_dir (StateDirBusy otherwise)
    try:
        gcs = build(config, backend)
        runner = asyncio.create_task(gcs.run(stop))
        if started is not None:
            opened = asyncio.create_task(gcs.ready.wait())
            await asyncio.wait({runner, opened}, return_when=asyncio.FIRST_COMPLETED)
            if opened.done():
                started(gcs)
            else:
                opened.cancel()
        await runner
    finally:
        lock.release()


def run(config: Config, backend: Backends) -> int:
    """Blocking: serve until SIGINT or SIGTERM; 0 on a clean stop, 1 on a failure. SIGHUP writes
    out changed state (parameters, signing timestamp) and serves on: the configuration is the
    embedding program's, so nothing is re-read, and a hangup never ends the program."""

    async def main() -> int:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for signum in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(signum, stop.set)
        running: list[Daemon] = []
        loop.add_signal_handler(signal.SIGHUP, lambda: running and running[0].sync_state())
        try:
            await serve(config, backend, stop, started=running.append)
        except Exception:  # noqa: BLE001  (an embedding program gets exit 1 and the traceback logged)
            import structlog
            structlog.get_logger("gcsd.embed").exception("embedded_daemon_failed")
            return 1
        return 0

    return asyncio.run(main())


__all__ = ["Backends", "Limits", "Setpoint", "VehicleBackend", "VehicleState", "build", "run", "serve"]
