"""The composition root: the one place that builds the daemon's parts and wires them.

`build(config, ...) -> Parts` makes what a Daemon serves with: the signing manager, the tlog,
the channels (each constructed with its receiver, the daemon, and the shared wake time, signing,
tlog and error counts), one vehicle node per simulated vehicle (parameters, state, autopilot,
links, the services of SERVICES in order, their message and command tables and their parameter
listeners), the router and the ingress decision over it (routing/ingress.py). Nothing else
constructs a service, registers a handler, a command, a parameter listener or a channel
(tests/unit/test_architecture.py).

Services are listed in SERVICES, in order: (name, factory(node, wiring) -> service or None).
Each declares what it handles (`handle_<MESSAGE>` methods, `commands()`); the tables are built
by `Registry`, which refuses an id registered twice unless OVERRIDES names the intended winner
and loser. The vehicle type's own command handlers (vehicles/commands.py) register last, as the
service "vehicle": a copter's CONDITION_YAW, a plane's DO_PAUSE_CONTINUE win over the generic
flight service's, and each of those is listed in OVERRIDES.

Adding a service: write it against `ServiceContext` (context.py), add one line to SERVICES (its
factory gets the node and the `Wiring` of the parts built before it), run the suite: the registry
says if one of its ids is taken. docs/architecture.md has the recipes.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.api.http import wiring as http_wiring
from gcsd.config import MAX_CHANNELS, ChannelConfig, Config
from gcsd.config.authority import read_key
from gcsd.config.mqtt import route_capacity
from gcsd.config.schema import LOCAL_TYPE, mavlink_slot
from gcsd.links.channel import Channel, Receiver
from gcsd.links.outbox import WakeTime
from gcsd.links.tlog import TlogWriter
from gcsd.payloads import build as payload
from gcsd.payloads.logs.wiring import flight_log_service, log_dir
from gcsd.persist import WriteBehind
from gcsd.routing.authority import ROLES
from gcsd.routing.ingress import Ingress
from gcsd.routing.router import MAX_ROUTES, Router, RouteTable
from gcsd.vehicle import telemetry
from gcsd.vehicle.autopilot.core import Autopilot
from gcsd.vehicle.node import VehicleNode
from gcsd.vehicle.params import ParamStore, sysids
from gcsd.vehicle.params.parmfile import read_parm
from gcsd.vehicle.services.commands import CommandService
from gcsd.vehicle.services.control import ControlService
from gcsd.vehicle.services.flight import FlightService
from gcsd.vehicle.services.ftp import FtpService
from gcsd.vehicle.services.highlatency import HighLatencyService
from gcsd.vehicle.services.maintenance import MaintenanceService
from gcsd.vehicle.services.mission import MissionService
from gcsd.vehicle.services.modes import ModesService
from gcsd.vehicle.services.params import ParamService
from gcsd.vehicle.services.peripherals import PeripheralService
from gcsd.vehicle.services.rates import RatesService
from gcsd.vehicle.services.signing import SigningService
from gcsd.vehicle.services.timesync import TimesyncService
from gcsd.vehicle.sim.swarm import initial_state
from gcsd.vehicle.types import vehicle_params, vehicle_type
from gcsd.wire.signing import SigningManager, SigningStore, StationKey
from gcsd.wire.streams import PARAM_SUFFIX, STREAM_NAMES

log = structlog.get_logger("gcsd.daemon.compose")

COMMAND, MESSAGE = "command", "message"

# (kind, id) -> (winner, loser): an id two services register on purpose. Anything else
# registered twice is a DuplicateRegistration at start.
OVERRIDES: dict[tuple[str, int | str], tuple[str, str]] = {
    # AVAILABLE_MODES is the modes service's; it hands every other REQUEST_MESSAGE to rates
    (COMMAND, M.MAV_CMD_REQUEST_MESSAGE): ("modes", "rates"),
    # the vehicle type's own handlers win over the generic flight and payload services'
    (COMMAND, M.MAV_CMD_DO_CHANGE_SPEED): ("vehicle", "flight"),
    (COMMAND, M.MAV_CMD_DO_CHANGE_ALTITUDE): ("vehicle", "flight"),
    (COMMAND, M.MAV_CMD_CONDITION_YAW): ("vehicle", "flight"),
    (COMMAND, M.MAV_CMD_DO_FLIGHTTERMINATION): ("vehicle", "flight"),
    (COMMAND, M.MAV_CMD_DO_PAUSE_CONTINUE): ("vehicle", "flight"),
    (COMMAND, M.MAV_CMD_NAV_LOITER_UNLIM): ("vehicle", "flight"),
    (COMMAND, M.MAV_CMD_DO_PARACHUTE): ("vehicle", "peripherals"),
    (COMMAND, M.MAV_CMD_AIRFRAME_CONFIGURATION): ("vehicle", "peripherals"),
    # a fitted gimbal, camera or CAN bus answers what peripherals answers "no such device" to
    **{(COMMAND, cmd): ("gimbal", "peripherals") for cmd in (
        M.MAV_CMD_DO_MOUNT_CONFIGURE, M.MAV_CMD_DO_MOUNT_CONTROL, M.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE,
        M.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, M.MAV_CMD_DO_SET_ROI_SYSID)},
    **{(COMMAND, cmd): ("camera", "peripherals") for cmd in (
        M.MAV_CMD_DO_DIGICAM_CONTROL, M.MAV_CMD_DO_SET_CAM_TRIGG_DIST, M.MAV_CMD_IMAGE_START_CAPTURE,
        M.MAV_CMD_IMAGE_STOP_CAPTURE, M.MAV_CMD_VIDEO_START_CAPTURE, M.MAV_CMD_VIDEO_STOP_CAPTURE,
        M.MAV_CMD_SET_CAMERA_FOCUS)},
    (COMMAND, M.MAV_CMD_CAN_FORWARD): ("can", "peripherals"),
}


class DuplicateRegistration(Exception):
    """A message or command id registered by two services without an entry in OVERRIDES."""


class Registry:
    """The dispatch tables of one node: message name -> handler, command id -> handler."""

    def __init__(self, overrides: dict[tuple[str, int | str], tuple[str, str]] = OVERRIDES) -> None:
        self.overrides = overrides
        self.handlers: dict[str, Callable] = {}
        self.commands: dict[int, Callable] = {}
        self.owner: dict[tuple[str, int | str], str] = {}
        self.overridden: set[tuple[str, int | str]] = set()  # the OVERRIDES entries that applied

    def add(self, name: str, service) -> None:
        for msg, handler in service.message_handlers().items():
            self._put(MESSAGE, msg, handler, name, self.handlers)
        for cmd, handler in service.commands().items():
            self._put(COMMAND, cmd, handler, name, self.commands)

    def add_commands(self, name: str, table: dict[int, Callable]) -> None:
        for cmd, handler in table.items():
            self._put(COMMAND, cmd, handler, name, self.commands)

    def _put(self, kind: str, key: int | str, handler: Callable, name: str, table: dict) -> None:
        prev = self.owner.get((kind, key))
        if prev is not None:
            rule = self.overrides.get((kind, key))
            if rule == (prev, name):
                self.overridden.add((kind, key))
                return  # the winner came first
            if rule == (name, prev):
                self.overridden.add((kind, key))
            else:
                raise DuplicateRegistration(
                    f"{kind} {key} is registered by {prev!r} and by {name!r}; list the intended winner in "
                    "compose.OVERRIDES")
        self.owner[(kind, key)] = name
        table[key] = handler


@dataclass
class Wiring:
    """What a service factory may use: the daemon's shared parts and the services built before."""

    config: Config
    signing: SigningManager
    services: dict[str, object] = field(default_factory=dict)


def _serial_control(node: VehicleNode, w: Wiring):
    if not w.config.serial_control or node.index != 0:  # one owner per device, even in a swarm
        return None
    from gcsd.vehicle.services.serialcontrol import SerialControlService
    return SerialControlService(node, w.config.serial_control)


# The services of a vehicle, in registration order: (name, factory(node, wiring) -> service | None).
# "params" and "commands" are built by build_vehicle itself (the node needs its parameters; the
# command service needs the whole command table) and take these places in the order.
SERVICES: tuple[tuple[str, Callable[[VehicleNode, Wiring], object]], ...] = (
    ("control", lambda node, w: ControlService(node)),
    ("rates", lambda node, w: RatesService(node, node.producers)),
    ("timesync", lambda node, w: TimesyncService(node)),
    ("params", lambda node, w: w.services["params"]),
    ("mission", lambda node, w: MissionService(node, w.config.mission, node.state_dir)),
    ("flight", lambda node, w: FlightService(node, w.services["mission"])),
    ("maintenance", lambda node, w: MaintenanceService(node, node.state_dir / w.config.ftp.root)),
    ("peripherals", lambda node, w: PeripheralService(node)),
    ("modes", lambda node, w: ModesService(node, w.services["rates"])),
    ("highlatency", lambda node, w: HighLatencyService(node)),
    ("serialcontrol", _serial_control),
    ("ftp", lambda node, w: FtpService(node, node.state_dir / w.config.ftp.root, w.config.ftp.max_file_bytes,
                                       w.services["params"], w.services["mission"],
                                       {"logs": log_dir(node.state_dir, w.config)})),
    ("signing", lambda node, w: SigningService(node, w.signing)),
    ("logs", lambda node, w: flight_log_service(node, w.config)),
    ("gimbal", payload.gimbal_service),  # these three: None unless configured (payload.py)
    ("camera", payload.camera_service),
    ("can", payload.can_service),
)


def vehicle_state_dir(config: Config, index: int) -> Path:
    """state_dir for a single vehicle; state_dir/vehicle-N for the N-th vehicle of a swarm."""
    if config.vehicle.count == 1:
        return Path(config.state_dir)
    return Path(config.state_dir) / f"vehicle-{index + 1}"


def _saved_sysid(config: Config, index: int) -> float:
    """The SYSID_THISMAV vehicle `index` saved (its configured sysid if none)."""
    configured = config.vehicle.sysid + index
    try:
        values, _ = read_parm(vehicle_state_dir(config, index) / "mav.parm")
    except OSError:
        return configured
    return values.get(sysids.NAME, configured)


def _start_sysid(node_index: int, config: Config, store: ParamStore, planned: int | None) -> None:
    """SYSID_THISMAV at start: the planned one (a swarm, params/sysids.py), or the saved one if it
    is a system id; else the configured one, logged, and saved by the boot count's save."""
    configured = config.vehicle.sysid + node_index
    wanted = store.get(sysids.NAME)
    use = planned if planned is not None else sysids.start_sysids([configured], [wanted])[0]
    if use != wanted:
        log.warning("sysid_fallback", vehicle=node_index + 1, saved=wanted, sysid=use,
                    reason="not a system id" if not sysids.valid(wanted) else "another vehicle's sysid")
        store.set(sysids.NAME, use, force=True)


def _vet_sysid(nodes: list[VehicleNode], index: int, name: str, value: float) -> str | None:
    if name != sysids.NAME:
        return None
    return sysids.clash(index, value, [n.sysid for n in nodes], [n.params.get(sysids.NAME) for n in nodes])


def build_vehicle(index: int, config: Config, clock, channels: list[Channel], wake: Callable[[Channel], None],
                  errors, signing: SigningManager, backend=None, services=None,
                  overrides=None, producers: dict | None = None, sysid: int | None = None) -> VehicleNode:
    """One vehicle node with its parameters, autopilot, services (SERVICES) and tables; `sysid`:
    the one a swarm planned for it (params/sysids.py)."""
    services = SERVICES if services is None else services
    overrides = OVERRIDES if overrides is None else overrides
    vcfg = config.vehicle
    vtype = vehicle_type(vcfg.type)
    state_dir = vehicle_state_dir(config, index)
    now = clock.now()
    store = ParamStore(payload.payload_params(vehicle_params(  # ArduPilot's set for the vehicle type
        vtype, vcfg.sysid + index, config.gcs.sysid, config.gcs.enforce_sysid,  # (gcsd.vehicle.params.defs)
        [dict(ch.config.streams) for ch in channels if ch.config.type != LOCAL_TYPE], vcfg.speedup,
    ), config))
    param_service = ParamService(None, store, state_dir / "mav.parm", now)
    param_service.load(config.params_file)
    _start_sysid(index, config, store, sysid)
    # write-behind of mav.parm: coalesced, on a worker thread, flushed by close()
    writer = WriteBehind(param_service.save_path, param_service, clock.now, errors=errors)
    param_service.on_dirty = writer.kick
    store.set("STAT_BOOTCNT", store.get("STAT_BOOTCNT") + 1, force=True)
    capacity = float(store.get("BATT_CAPACITY")) if "BATT_CAPACITY" in store else 0.0
    node = VehicleNode(index, vtype, clock, channels, store, initial_state(vtype, vcfg.home, index, capacity),
                       vcfg.compid, state_dir, wake, errors, dict(producers or telemetry.producers()),
                       param_service.save)  # each vehicle its own table: a gimbal adds to it
    node.flushers.append(writer.flush)
    node.syncers.append(writer.sync)
    param_service.ctx = node
    node.autopilot = Autopilot(node, backend, now, vcfg.speedup)  # the vehicle: autopilot over a backend
    _wire_params(node, config, clock)

    w = Wiring(config, signing, {"params": param_service})
    registry = Registry(overrides)
    built: list = []
    for name, factory in services:
        service = factory(node, w)
        if service is None:
            continue
        w.services[name] = service
        built.append(service)
        registry.add(name, service)
    # the vehicle type's own command handlers, last, each given the vehicle's context
    registry.add_commands("vehicle", {cmd: functools.partial(h, node) for cmd, h in vtype.commands.items()})
    commands = CommandService(node, registry.commands)
    registry.add("commands", commands)
    built.append(commands)
    for service in built:
        for compid, table in service.local_components().items():
            commands.add_component(compid, table)
            node.local_compids.append(compid)
    node.control = w.services["control"]
    node.plans = w.services["mission"]
    node.attach(built, registry.handlers)
    node.flushers.append(w.services["mission"].close)  # an upload's plan write in flight
    node.registry = registry  # who registered what (tests/unit/test_architecture.py)
    param_service.save()  # the boot count
    return node


def _wire_params(node: VehicleNode, config: Config, clock) -> None:
    """Parameters that act at once; the rest are read where they are used."""
    params = node.params
    for link in node.links:
        slot = mavlink_slot([ch.config.type for ch in node.channels], link.channel.index)
        for stream in STREAM_NAMES:
            name = None if slot is None else f"SR{slot}_{PARAM_SUFFIX[stream]}"
            if name not in params:  # the HTTP API's channel, or a stream the type has no SRn_ for
                link.set_stream_rate(stream, link.channel.config.streams[stream], clock.now())
                continue
            link.set_stream_rate(stream, params.clamped(name), clock.now())  # beyond its range: the bound
    for slot in range(MAX_CHANNELS):  # also the slots of channels added at run time (node.attach_link)
        for stream in STREAM_NAMES:
            name = f"SR{slot}_{PARAM_SUFFIX[stream]}"
            if name in params:
                params.on_change(name, lambda n, _v, slot=slot, stream=stream:
                                 node.set_slot_rate(slot, stream, params.clamped(n), clock.now()))
    node.gcs_sysid = int(params.get("SYSID_MYGCS")) if "SYSID_MYGCS" in params else config.gcs.sysid
    node.enforce_gcs_sysid = (bool(params.get("SYSID_ENFORCE")) if "SYSID_ENFORCE" in params
                              else config.gcs.enforce_sysid)
    params.on_change("SYSID_MYGCS", lambda _n, v: setattr(node, "gcs_sysid", int(v)))
    params.on_change("SYSID_ENFORCE", lambda _n, v: setattr(node, "enforce_gcs_sysid", bool(v)))
    params.on_change("BATT_CAPACITY", lambda n, _v: setattr(node.state, "capacity_mah", float(params.clamped(n))))


@dataclass(frozen=True)
class ChannelParts:
    """What every channel of a daemon is built with (at start, and for one added at run time)."""

    receiver: Receiver  # the daemon
    wake_time: WakeTime
    signing: object
    tlog: TlogWriter | None
    errors: object
    clock: object
    signing_required: bool


@dataclass(frozen=True)
class Parts:
    """What a daemon serves with, built once (daemon.py): nothing is wired onto it afterwards."""

    signing_manager: SigningManager
    signing_writer: WriteBehind  # the signing timestamp, saved every SAVE_INTERVAL_S off the loop
    tlog: TlogWriter | None
    wake_time: WakeTime  # the asyncio layer's time at each wake-up, shared by every channel
    channels: list[Channel]
    nodes: list[VehicleNode]
    router: Router
    ingress: Ingress
    taps: list  # tap(channel, frame, now) of every accepted frame, before routing
    channel_parts: ChannelParts  # for a channel added at run time


def build(config: Config, clock, errors, receiver, channels, wake_node, backend=None,
          producers: dict | None = None) -> Parts:
    """Everything a daemon serves with: signing, tlog, channels (frames to `receiver`), vehicles
    (`wake_node(index, channel)`), router and ingress."""
    signing_manager = SigningManager(
        config.signing.key, config.signing.require, SigningStore(Path(config.state_dir) / "signing.key"),
        clock.wall(),
    )
    signing_writer = WriteBehind(signing_manager.store.path, signing_manager, clock.now,
                                 write=SigningStore.write, errors=errors)  # mode 0600, atomic
    tlog = TlogWriter(config.log.tlog) if config.log.tlog else None
    wake_time = WakeTime()
    parts = ChannelParts(receiver, wake_time, signing_manager.signing, tlog, errors, clock, config.signing.require)
    # the HTTP API's own channel comes after the configured ones (gcsd.api.http.wiring)
    chans = [channel(parts, i, c) for i, c in enumerate([*channels, *http_wiring.channel_configs(config)])]
    count = config.vehicle.count
    planned = sysids.start_sysids([config.vehicle.sysid + i for i in range(count)],
                                  [_saved_sysid(config, i) for i in range(count)]) if count > 1 else [None]
    nodes = [
        build_vehicle(i, config, clock, chans, functools.partial(wake_node, i), errors,
                      signing_manager, backend=None if backend is None else backend(i), producers=producers,
                      sysid=planned[i])
        for i in range(count)
    ]
    if count > 1:  # a swarm refuses a SYSID_THISMAV another vehicle has (params/sysids.py)
        for i, node in enumerate(nodes):
            for service in node.services:
                if isinstance(service, ParamService):
                    service.vet = functools.partial(_vet_sysid, nodes, i)
    router = Router({(n.sysid, c) for n in nodes for c in (n.compid, *n.local_compids)},
                    [ch.policy for ch in chans],
                    RouteTable(route_capacity((c.type for c in config.channels), MAX_ROUTES)))
    taps = [service.tap for n in nodes for service in n.services if hasattr(service, "tap")]
    ingress = Ingress(router, signing_manager.signing, config.routing.dedup_ms)
    signing_manager.signing.set_keys(station_keys(config))
    ingress.set_roles([ROLES[ch.config.role] for ch in chans], bool(config.signing.keys))
    return Parts(signing_manager, signing_writer, tlog, wake_time, chans, nodes, router, ingress, taps, parts)


def station_keys(config: Config) -> tuple[StationKey, ...]:
    """signing.keys read from their files (preflight has checked them)."""
    return tuple(StationKey(k.name, read_key(k, Path), ROLES[k.role]) for k in config.signing.keys)


def channel(parts: ChannelParts, index: int, config: ChannelConfig) -> Channel:
    """A channel connected to the daemon's receive path, signing, tlog and error boundary (at
    start, and for a channel added at run time: livechannels.py)."""
    ch = http_wiring.channel_class(config)(
        index, config, parts.clock.now, receiver=parts.receiver, wake_time=parts.wake_time,
        signing=parts.signing, tlog=parts.tlog, errors=parts.errors, wall=parts.clock.wall,
        signing_required=parts.signing_required)
    return ch
