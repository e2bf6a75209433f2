"""The shape of the code, checked (REVIEW.md section F, issue 18).

- No import circle in src (TYPE_CHECKING imports count: a circle means two modules cannot be
  read apart).
- The composition root is the only place that registers: a message or command id registered
  twice without an entry in compose.OVERRIDES stops the build; each override is used.
- Services, the vehicle types' handlers, the autopilot and the telemetry producers see the
  vehicle only through the ServiceContext / TelemetryView members (context.py,
  telemetry/view.py): none reaches the node, its simulation or another service.
"""

from __future__ import annotations

import ast
import itertools
import sys
from pathlib import Path

import pytest
import yaml
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.boundary import ErrorCounts
from gcsd.clock import Clock
from gcsd.config import VEHICLE_TYPES, parse_config
from gcsd.daemon.compose import COMMAND, OVERRIDES, DuplicateRegistration, Registry, build_vehicle
from gcsd.links.channel import Channel
from gcsd.vehicle.context import CONTEXT_MEMBERS
from gcsd.vehicle.services import Service
from gcsd.vehicle.telemetry.view import VIEW_MEMBERS
from gcsd.wire.signing import SigningManager

SRC = Path(__file__).resolve().parents[2] / "src"
PACKAGE = SRC / "gcsd"


# --- import circles -----------------------------------------------------------------------------

def import_graph(root: Path = SRC) -> dict[str, set[str]]:
    """module -> modules it imports, TYPE_CHECKING imports included (a package's __init__ is a
    module, its own imports are not followed, as /work/shared/hooks/before-stop does)."""
    mods = {}
    for p in root.rglob("*.py"):
        parts = list(p.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = p
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for m, p in mods.items():
        if p.name == "__init__.py":
            continue
        pkg = m.split(".")[:-1]
        for n in ast.walk(ast.parse(p.read_text())):
            if isinstance(n, ast.ImportFrom):
                base = pkg[: len(pkg) - (n.level - 1)] if n.level else []
                prefix = ".".join(base + ([n.module] if n.module else [])) if n.level else (n.module or "")
                for a in n.names:
                    target = f"{prefix}.{a.name}" if f"{prefix}.{a.name}" in mods else prefix
                    if target in mods and target != m:
                        edges[m].add(target)
            elif isinstance(n, ast.Import):
                edges[m].update(a.name for a in n.names if a.name in mods and a.name != m)
    return edges


def circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10000))

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in edges:
        if v not in index:
            visit(v)
    return out


def test_src_has_no_import_circle_type_checking_imports_included():
    assert circles(import_graph()) == []


def test_the_circle_check_sees_a_type_checking_circle(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from . import b\n")
    (pkg / "b.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .a import thing\n")
    (pkg / "c.py").write_text("from .a import b\n")
    assert circles(import_graph(tmp_path)) == [["pkg.a", "pkg.b"]]


# --- one registration per id ----------------------------------------------------------------------

class _Cmd(Service):
    def __init__(self, command: int) -> None:
        self.command = command
        self.handler = lambda req: M.MAV_RESULT_ACCEPTED

    def commands(self):
        return {self.command: self.handler}


class _Msg(Service):
    def handle_PING(self, inc) -> None:
        pass


def test_a_command_registered_twice_without_an_override_stops_the_build():
    registry = Registry({})
    registry.add("first", _Cmd(M.MAV_CMD_DO_SET_MODE))
    with pytest.raises(DuplicateRegistration, match="command 176 .*'first'.*'second'"):
        registry.add("second", _Cmd(M.MAV_CMD_DO_SET_MODE))


def test_a_message_registered_twice_without_an_override_stops_the_build():
    registry = Registry({})
    registry.add("first", _Msg())
    with pytest.raises(DuplicateRegistration, match="message PING"):
        registry.add("second", _Msg())


@pytest.mark.parametrize("order", [("winner", "loser"), ("loser", "winner")])
def test_an_override_names_the_winner_whatever_the_order(order):
    registry = Registry({(COMMAND, M.MAV_CMD_DO_SET_MODE): ("winner", "loser")})
    services = {"winner": _Cmd(M.MAV_CMD_DO_SET_MODE), "loser": _Cmd(M.MAV_CMD_DO_SET_MODE)}
    for name in order:
        registry.add(name, services[name])
    assert registry.owner[(COMMAND, M.MAV_CMD_DO_SET_MODE)] == "winner"
    assert registry.commands[M.MAV_CMD_DO_SET_MODE] is services["winner"].handler


PAYLOAD = {"vehicle": {"camera": True, "gimbal": True},
           "can": {"buses": [{"interface": "virtual", "channel": "architecture"}]}}


def _build(tmp_path, vehicle: str, overrides=OVERRIDES, payload: bool = False):
    data = {"vehicle": {"type": vehicle}, "state_dir": str(tmp_path / vehicle / str(payload)),
            "channels": [{"name": "gcs", "type": "udp-server", "address": "127.0.0.1:0"}]}
    if payload:  # the camera, the gimbal and a CAN bus on: the services that override peripherals
        data = {**data, **PAYLOAD, "vehicle": {**data["vehicle"], **PAYLOAD["vehicle"]}}
    config = parse_config(yaml.safe_dump(data), "t.yaml")
    clock = Clock(monotonic=lambda: 100.0, wall=lambda: 1.8e9)
    channel = Channel(0, config.channels[0], clock.now)
    return build_vehicle(0, config, clock, [channel], lambda ch: None, ErrorCounts(),
                         SigningManager(None, False, None, clock.wall()), overrides=overrides)


def test_every_vehicle_type_builds_and_every_override_is_one_that_happens(tmp_path):
    used = set()
    for vehicle, payload in itertools.product(VEHICLE_TYPES, (False, True)):
        node = _build(tmp_path, vehicle, payload=payload)
        used |= node.registry.overridden
        assert {type(s).__name__ for s in node.services} >= {"ControlService", "CommandService", "MissionService"}
        for service in node.services:
            if hasattr(service, "shutdown"):
                service.shutdown(0.0)  # the CAN bus closed
    assert used == set(OVERRIDES), f"overrides no vehicle type needs: {set(OVERRIDES) - used}"


def test_without_the_overrides_the_real_tables_do_not_build(tmp_path):
    with pytest.raises(DuplicateRegistration, match="REQUEST_MESSAGE|command 512"):
        _build(tmp_path, "sub", overrides={})


# --- the narrow context ---------------------------------------------------------------------------

VEHICLE = PACKAGE / "vehicle"
PAYLOADS = PACKAGE / "payloads"
CONTEXT_USERS = [*sorted((VEHICLE / "services").glob("*.py")), *sorted((VEHICLE / "autopilot").glob("*.py")),
                 PAYLOADS / "gimbal" / "service.py", PAYLOADS / "camera" / "service.py", PAYLOADS / "can" / "service.py",
                 VEHICLE / "types" / "commands.py", VEHICLE / "types" / "prearm.py",
                 VEHICLE / "types" / "health.py", VEHICLE / "types" / "motors.py"]
VIEW_USERS = sorted((VEHICLE / "telemetry").glob("*.py"))


def _reached(path: Path) -> set[str]:
    """Members read as `ctx.X` or `self.ctx.X` (and anything read off `node`)."""
    out = set()
    for n in ast.walk(ast.parse(path.read_text())):
        if not isinstance(n, ast.Attribute):
            continue
        v = n.value
        if isinstance(v, ast.Name) and v.id in ("ctx", "node"):
            out.add(f"{v.id}.{n.attr}")
        elif isinstance(v, ast.Attribute) and v.attr in ("ctx", "node") and isinstance(v.value, ast.Name):
            out.add(f"{v.attr}.{n.attr}")
    return out


@pytest.mark.parametrize("path", CONTEXT_USERS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_services_reach_only_the_service_context(path):
    reached = _reached(path)
    assert not {r for r in reached if r.startswith("node.")}, "a service reaches the node"
    assert {r[len("ctx."):] for r in reached} <= CONTEXT_MEMBERS, "members outside ServiceContext"


@pytest.mark.parametrize("path", VIEW_USERS, ids=lambda p: p.name)
def test_telemetry_producers_read_only_the_view(path):
    reached = {r[len("ctx."):] for r in _reached(path) if r.startswith("ctx.")}
    assert reached <= VIEW_MEMBERS


def test_no_module_reaches_the_simulation_or_control_through_a_node_or_by_getattr():
    banned = ("node.sim", "node.control", "getattr(node", "getattr(self.node", "getattr(self.ctx", "getattr(ctx,")
    scanned = [p for d in ("services", "types", "autopilot", "telemetry") for p in (VEHICLE / d).rglob("*.py")]
    found = [f"{p.relative_to(PACKAGE)}: {b}" for p in scanned for b in banned if b in p.read_text()]
    assert found == []
