"""Docs that work: every command line in README.md, docs/, sitl/ and systemd/ is exercised.

Command lines are taken from fenced code blocks, from inline code spans that start with a
program name, and from the comment headers of sitl/*.yaml, sitl/embed_robot.py and the systemd
unit. Each is classified by its program, and an unknown program fails the test, so a new command
in the docs needs a check here:
- `gcsd ...`: parsed by gcsd's own argument parser (synopsis brackets and FILE placeholders
  resolved); `gcsd --version` and `gcsd check-config FILE` are run; `gcsd` and `gcsd -c FILE`
  (the default, every sitl configuration) are started in a scratch directory, must answer a
  ground station's HEARTBEAT on the documented port (udpout:127.0.0.1:14551), and must stop
  with exit 0 on SIGTERM.
- the documented ground-station URLs are used for real against `gcsd` with the default
  configuration: MAVProxy's `--master`, MAVSDK's `udpout://`, pymavlink's `mavlink_connection`;
  and the default's broadcast channel is found by a listener on UDP 14550, as QGroundControl.
- `python sitl/... | bench/...`: the script's `--help` must accept every option the docs use.
- the test command is `.ci/run`'s last line; install and administration lines (pip, systemctl,
  useradd, ...) are not run here, but every project file they name must exist.
Also: no document refers to a file that is not in the project (Markdown links and `NAME.md`
mentions must exist; nothing points into ../shared).
"""

from __future__ import annotations

import asyncio
import fcntl
import os
import re
import select
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.daemon import cli

REPO = Path(__file__).resolve().parents[2]
MARKDOWN = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md")), *sorted((REPO / "sitl").rglob("*.md")),
            REPO / "systemd" / "README.md"]
HEADERS = [*sorted((REPO / "sitl").glob("*.yaml")), REPO / "sitl" / "embed_robot.py",
           REPO / "systemd" / "gcsd.service", REPO / "config" / "gcsd.yaml"]
PROGRAMS = ("gcsd", "mavproxy.py", "python", "python3", "pip", "systemctl", "journalctl", "useradd",
            "install", "ln", "apt-get", "kill")
# not run: files checked (kill: the unit's ExecReload, SIGHUP to the daemon; tests/integration/test_companion_live.py)
ADMIN = ("pip", "systemctl", "journalctl", "useradd", "install", "ln", "apt-get", "kill")
API_PORT = 14551  # the default configuration's udp-server (README "Connect a ground station")
START_TIMEOUT_S = 15.0
PORTS_LOCK = Path(tempfile.gettempdir()) / "gcsd-tests-documented-ports.lock"
PORTS_LOCK_WAIT_S = 180.0


@pytest.fixture(autouse=True)
def documented_ports():
    """The documented ports (UDP 14551, the broadcast to 14550) are fixed: one test at a time uses
    them, across pytest-xdist workers (README's command) and across test runs on this machine."""
    with PORTS_LOCK.open("a") as lock:
        end = time.monotonic() + PORTS_LOCK_WAIT_S
        while True:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > end:
                    pytest.fail(f"{PORTS_LOCK} held for {PORTS_LOCK_WAIT_S} s by another test run")
                time.sleep(0.1)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


@dataclass(frozen=True)
class Command:
    source: str
    text: str

    @property
    def argv(self) -> list[str]:
        words = shlex.split(self.text.replace("[", " ").replace("]", " "))
        while words and (words[0] in ("sudo", "/usr/bin/env") or "=" in words[0]):
            words = words[3:] if words[:2] == ["sudo", "-u"] else words[1:]
        if words and ("/bin/" in words[0] or words[0].startswith(".venv/")):
            words[0] = words[0].rsplit("/", 1)[-1]  # .venv/bin/gcsd, /opt/gcsd/bin/pip
        return words


def _split(line: str) -> list[str]:
    line = re.sub(r"\s+#\s.*$", "", line).strip()
    return [part.strip() for part in line.split("&&") if part.strip()]


def _is_program(text: str) -> bool:
    try:
        words = Command("", text).argv
    except ValueError:
        return False
    return bool(words) and words[0] in PROGRAMS


# in comment headers: `gcsd SUBCOMMAND ...`, `mavproxy.py --master=URL`, `python sitl/x.py ...`
_HEADER_COMMAND = re.compile(
    r"(gcsd (?:-c|run|check-config|status|--version)\b[^;`)#\n]*?"
    r"|mavproxy\.py --master=[^\s`;)]+?|python3? (?:sitl|bench)/\S+[^;`)#\n]*?)"
    r"(?=\.?\s*$|\.?\s{2,}|;|\)|`|#|\.\s)")


def documented_commands() -> list[Command]:
    found: list[Command] = []
    for path in MARKDOWN:
        text = path.read_text(encoding="utf-8")
        name = str(path.relative_to(REPO))
        for block in re.findall(r"^\s*```(?:sh|bash|console|shell)?\n(.*?)^\s*```", text, re.MULTILINE | re.DOTALL):
            for line in block.splitlines():
                if line.strip() and not line.strip().startswith("#"):
                    found += [Command(name, part) for part in _split(line)]
        prose = re.sub(r"^\s*```.*?^\s*```", "", text, flags=re.MULTILINE | re.DOTALL)
        for line in re.findall(r"^ {4}(\S.*)$", prose, re.MULTILINE):  # indented code blocks
            found += [Command(name, part) for part in _split(line) if _is_program(part)]
        for span in re.findall(r"`([^`\n]+)`", prose):
            if _is_program(span):
                found.append(Command(name, span.strip()))
    for path in HEADERS:
        name = str(path.relative_to(REPO))
        for line in path.read_text(encoding="utf-8").splitlines():
            if path.suffix == ".service":
                if line.startswith(("ExecStart", "ExecStartPre", "ExecReload")):
                    found.append(Command(name, line.split("=", 1)[1]))
            elif line.lstrip().startswith("#") or (path.suffix == ".py" and line.startswith(("    ", "Then"))):
                found += [Command(name, m.strip()) for m in _HEADER_COMMAND.findall(line) if _is_program(m.strip())]
    return found


def _by_program(program: str) -> list[Command]:
    return [c for c in documented_commands() if c.argv and c.argv[0] == program]


def _resolve_placeholders(argv: list[str]) -> list[str]:
    return ["config/gcsd.yaml" if word == "FILE" else word for word in argv]


# --- what the docs say, checked without running anything -------------------------------------------


def kind(command: Command) -> str | None:
    """Which check covers a command line (None: no check knows it, which fails the test)."""
    argv = command.argv
    if not argv:
        return None
    program = argv[0]
    if program in ("gcsd", "mavproxy.py") or program in ADMIN:
        return program if program not in ADMIN else "admin"
    if program in ("python", "python3"):
        if argv[1:3] == ["-m", "venv"]:
            return "venv"
        if argv[1:3] == ["-m", "pytest"]:
            return "pytest"
        if argv[1:3] == ["-m", "bench"]:
            return "bench"
        if len(argv) > 1 and (REPO / argv[1]).is_file():
            return "script"
    return None


def test_the_docs_have_commands_and_every_one_is_of_a_known_kind():
    commands = documented_commands()
    assert len(commands) > 20, commands
    unknown = [c for c in commands if kind(c) is None]
    assert unknown == [], "commands in the docs that test_docs does not know how to check"


def test_every_mavproxy_master_is_a_udp_server_port_of_the_configuration_it_is_for():
    from gcsd.config import default_config, load_config

    def server_ports(config) -> set[int]:
        return {c.address[1] for c in config.channels if c.type == "udp-server"}

    for command in _by_program("mavproxy.py"):
        [master] = [w for w in command.argv if w.startswith("--master=udpout:")]
        port = int(master.rpartition(":")[2])
        source = REPO / command.source
        if source.suffix == ".yaml":
            ports = server_ports(load_config(source))
        elif source.parent.name == "fleet":
            ports = set().union(*(server_ports(load_config(p)) for p in source.parent.glob("*.yaml")))
        else:
            ports = server_ports(default_config())
        assert port in ports, f"{command.source}: `{command.text}` but the udp-server ports are {ports}"


def test_python_m_bench_runs():
    assert any(kind(c) == "bench" for c in documented_commands())
    out = subprocess.run([sys.executable, "-m", "bench", "--help"], check=False, capture_output=True, text=True, timeout=60,
                         cwd=REPO, env=_env())
    assert out.returncode == 0 and "usage" in out.stdout, out.stderr


def test_every_gcsd_command_line_is_accepted_by_the_cli_parser():
    commands = _by_program("gcsd")
    assert any(c.argv == ["gcsd", "-c", "sitl/plane.yaml"] for c in commands)
    for command in commands:
        argv = _resolve_placeholders(command.argv[1:])
        try:
            cli._parser().parse_args(argv)
        except SystemExit as exc:
            if argv == ["--version"] and exc.code == 0:
                continue
            pytest.fail(f"{command.source}: `{command.text}` is refused by gcsd's parser")


def test_the_readme_test_command_is_what_ci_runs():
    readme = (REPO / "README.md").read_text()
    ci_lines = (REPO / ".ci" / "run").read_text().splitlines()
    test_line = next(line for line in readme.splitlines() if "pytest" in line and line.startswith("python3 -m venv"))
    assert test_line in ci_lines


def test_files_named_by_install_and_administration_lines_exist():
    for command in documented_commands():
        if command.argv and command.argv[0] in ADMIN:
            for word in command.argv[1:]:
                if "/" in word and not word.startswith(("/", "-")) and "gcsd" not in word.split("/")[0]:
                    assert (REPO / word).exists(), f"{command.source}: `{command.text}` names {word}, missing"


def test_no_document_refers_to_a_file_outside_the_project():
    names = {p.name for p in REPO.rglob("*.md") if ".venv" not in p.parts}
    for path in MARKDOWN:
        text = path.read_text(encoding="utf-8")
        assert "../shared" not in text, path
        for target in re.findall(r"\]\(([^)#\s]+)", text):
            if not target.startswith(("http://", "https://", "mailto:")):
                assert (path.parent / target).exists(), f"{path.relative_to(REPO)} links to {target}, missing"
        for mention in re.findall(r"\b([A-Za-z_][\w-]*\.md)\b", text):
            assert mention in names, f"{path.relative_to(REPO)} mentions {mention}, which is not in the project"


def test_every_option_the_docs_give_a_script_is_in_its_help():
    scripts: dict[str, list[Command]] = {}
    for command in documented_commands():
        if kind(command) == "script":
            scripts.setdefault(command.argv[1], []).append(command)
    assert "sitl/embed_robot.py" in scripts
    for script, uses in scripts.items():
        helptext = subprocess.run([sys.executable, str(REPO / script), "--help"], check=False, capture_output=True, text=True,
                                  timeout=30, env=_env(), cwd=REPO)
        assert helptext.returncode == 0, f"{script} --help: {helptext.stderr}"
        for command in uses:
            for option in (w.split("=")[0] for w in command.argv[2:] if w.startswith("--")):
                assert option in helptext.stdout, f"{command.source}: {option} is not an option of {script}"


# --- what the docs say, run --------------------------------------------------------------------------


def _gcsd_argv(args: list[str]) -> list[str]:
    return [sys.executable, "-m", "gcsd", *args]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO / "src"), os.environ.get("PYTHONPATH")]))}


def test_gcsd_version_and_check_config_run_as_documented(tmp_path):
    commands = _by_program("gcsd")
    ran = 0
    for command in commands:
        argv = command.argv[1:]
        if argv == ["--version"]:
            out = subprocess.run(_gcsd_argv(argv), check=False, capture_output=True, text=True, timeout=30, env=_env())
            assert out.returncode == 0 and out.stdout.startswith("gcsd "), out
            ran += 1
        elif argv[:1] == ["check-config"] and (REPO / argv[1]).exists():
            out = subprocess.run(_gcsd_argv(argv), check=False, capture_output=True, text=True, timeout=30, env=_env(), cwd=REPO)
            assert out.returncode == 0, f"{command.source}: `{command.text}`: {out.stdout}{out.stderr}"
            ran += 1
    assert ran >= 1


def _heartbeat_bytes() -> bytes:
    mav = M.MAVLink(None, srcSystem=255, srcComponent=190)
    return mav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(mav)


def _first_vehicle_heartbeat(port: int, proc: subprocess.Popen, timeout_s: float = START_TIMEOUT_S) -> float:
    """Send a GCS HEARTBEAT to 127.0.0.1:port until a vehicle HEARTBEAT comes back; returns when."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    parser = M.MAVLink(None)
    parser.robust_parsing = True
    end = time.monotonic() + timeout_s
    try:
        while time.monotonic() < end:
            assert proc.poll() is None, f"gcsd exited with {proc.returncode}"
            sock.sendto(_heartbeat_bytes(), ("127.0.0.1", port))
            if select.select([sock], [], [], 0.2)[0]:
                for msg in parser.parse_buffer(sock.recv(65536)) or []:
                    if msg.get_type() == "HEARTBEAT" and msg.type != M.MAV_TYPE_GCS:
                        return time.monotonic()
        pytest.fail(f"no vehicle HEARTBEAT on 127.0.0.1:{port} within {timeout_s} s")
    finally:
        sock.close()


def _wait_until_free(port: int, timeout_s: float = 30.0) -> None:
    """The documented port is fixed: wait while another process (another test run) holds it."""
    end = time.monotonic() + timeout_s
    while True:
        probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            probe.bind(("0.0.0.0", port))
            return
        except OSError:
            if time.monotonic() > end:
                pytest.fail(f"UDP {port} is held by another process on this machine")
            time.sleep(0.2)
        finally:
            probe.close()


class Started:
    """`gcsd ARGS` in a scratch directory, once it logged daemon_ready: its own channels are bound
    and its signal handlers installed, so the fixed port answers for this daemon and not for one
    that another test run on the machine started meanwhile (that one would make ours exit 1)."""

    def __init__(self, args: list[str], cwd: Path) -> None:
        _wait_until_free(API_PORT)
        self.proc = subprocess.Popen(_gcsd_argv(args), cwd=cwd, env=_env(), stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, start_new_session=True)
        self.output: list[str] = []
        self._ready = threading.Event()
        threading.Thread(target=self._read, daemon=True).start()
        if not self._ready.wait(START_TIMEOUT_S):
            self.stop()
            pytest.fail(f"`gcsd {' '.join(args)}` not ready in {START_TIMEOUT_S} s:\n{''.join(self.output[-20:])}")

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.output.append(line)
            if "daemon_ready" in line:
                self._ready.set()
        self._ready.set()  # it exited: the caller sees proc.poll()

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
        try:
            return self.proc.wait(10.0)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait(5.0)
            return -9


def _documented_runs() -> list[tuple[str, list[str]]]:
    """(where, args) of every documented start of the daemon: `gcsd`, `gcsd run`, `gcsd -c FILE`."""
    runs: dict[tuple[str, ...], str] = {}
    for command in _by_program("gcsd"):
        args = command.argv[1:]
        if args[:1] in ([], ["run"], ["-c"]) and "FILE" not in args and "/etc" not in " ".join(args):
            runs.setdefault(tuple(args), command.source)
    return [(where, list(args)) for args, where in runs.items()]


@pytest.mark.parametrize("where,args", _documented_runs(), ids=lambda v: " ".join(v) if isinstance(v, list) else v)
def test_each_documented_start_answers_on_the_documented_port_and_stops_cleanly(where, args, tmp_path):
    shutil.copytree(REPO / "sitl", tmp_path / "sitl", ignore=shutil.ignore_patterns("*-state", "__pycache__"))
    shutil.copytree(REPO / "config", tmp_path / "config")
    daemon = Started(args, tmp_path)
    try:
        _first_vehicle_heartbeat(API_PORT, daemon.proc)
    finally:
        code = daemon.stop()
    assert code == 0, f"{where}: `gcsd {' '.join(args)}` exited {code} on SIGTERM"


@pytest.fixture
def default_daemon(tmp_path):
    daemon = Started([], tmp_path)
    _first_vehicle_heartbeat(API_PORT, daemon.proc)
    yield daemon
    assert daemon.stop() == 0


def _documented_url(pattern: str) -> str:
    text = (REPO / "README.md").read_text()
    match = re.search(pattern, text)
    assert match, f"README.md has no {pattern}"
    return match.group(1)


def test_the_documented_mavproxy_line_connects_to_the_default_configuration(default_daemon, tmp_path):
    [line] = {c.text for c in _by_program("mavproxy.py") if c.source == "README.md"}
    script = shutil.which("mavproxy.py", path=str(Path(sys.executable).parent)) or shutil.which("mavproxy.py")
    if script is None:
        pytest.skip("mavproxy.py is not installed")
    argv = [sys.executable, script, *shlex.split(line)[1:], "--no-state", "--default-modules=", "--non-interactive"]
    proc = subprocess.Popen(argv, cwd=tmp_path, env={**_env(), "HOME": str(tmp_path)}, stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    seen: list[str] = []
    try:
        end = time.monotonic() + 20.0
        while time.monotonic() < end:
            if not select.select([proc.stdout], [], [], 0.5)[0]:
                continue
            line_out = proc.stdout.readline()
            if not line_out:
                break
            seen.append(line_out)
            if "Detected vehicle 1:1" in line_out:
                break
        assert any("Detected vehicle 1:1" in s for s in seen), "".join(seen[-20:])
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(5.0)


def test_the_documented_mavsdk_and_pymavlink_urls_connect_to_the_default_configuration(default_daemon):
    mavsdk_url = _documented_url(r'add_any_connection\("(udpout://[^"]+)"\)')
    pymavlink_url = _documented_url(r'mavlink_connection\("(udpout:[^"]+)"\)')
    from pymavlink import mavutil

    conn = mavutil.mavlink_connection(pymavlink_url, source_system=255, source_component=190)
    try:
        conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        assert conn.recv_match(type="HEARTBEAT", blocking=True, timeout=5.0) is not None
    finally:
        conn.close()
    mavsdk = pytest.importorskip("mavsdk.asyncio", reason="mavsdk is a test extra")

    async def connect() -> bool:
        m = mavsdk.Mavsdk(mavsdk.Configuration.create_with_component_type(mavsdk.ComponentType.GROUND_STATION))
        try:
            await m.add_any_connection(mavsdk_url)
            return await m.first_autopilot(timeout_s=10.0) is not None
        finally:
            m.destroy()

    assert asyncio.run(connect())


def _limited_broadcast_reaches(listener: socket.socket) -> bool:
    """Whether a datagram to 255.255.255.255 reaches `listener` here (it needs a route)."""
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    probe.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
    try:
        probe.sendto(b"probe", ("255.255.255.255", listener.getsockname()[1]))
    except OSError:
        return False
    finally:
        probe.close()
    if not select.select([listener], [], [], 1.0)[0]:
        return False
    listener.recv(100)
    return True


def test_the_default_configuration_is_found_by_a_listener_on_14550_as_qgroundcontrol(tmp_path):
    """QGroundControl binds UDP 14550 on every address and waits: the default's broadcast channel
    reaches it (255.255.255.255 is delivered to wildcard-bound sockets of this host too)."""
    listener = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        listener.bind(("0.0.0.0", 14550))
    except OSError:
        listener.close()
        pytest.skip("UDP 14550 is in use on this machine")
    if not _limited_broadcast_reaches(listener):
        listener.close()
        pytest.skip("255.255.255.255 has no route on this machine (no network interface but lo)")
    daemon = Started([], tmp_path)
    parser = M.MAVLink(None)
    parser.robust_parsing = True
    try:
        found = None
        end = time.monotonic() + START_TIMEOUT_S
        while found is None and time.monotonic() < end:
            if select.select([listener], [], [], 0.2)[0]:
                data, source = listener.recvfrom(65536)
                for msg in parser.parse_buffer(data) or []:
                    if msg.get_type() == "HEARTBEAT" and msg.type == M.MAV_TYPE_QUADROTOR:
                        found = source
        assert found is not None, "no HEARTBEAT on UDP 14550 from the default configuration"
        listener.sendto(_heartbeat_bytes(), found)  # answer it, as QGroundControl does
        request = M.MAVLink(None, srcSystem=255, srcComponent=190)
        listener.sendto(request.param_request_read_encode(1, 1, b"SYSID_THISMAV", -1).pack(request), found)
        end = time.monotonic() + 5.0
        answered = False
        while not answered and time.monotonic() < end:
            if select.select([listener], [], [], 0.2)[0]:
                for msg in parser.parse_buffer(listener.recv(65536)) or []:
                    answered = answered or msg.get_type() == "PARAM_VALUE"
        assert answered, "the vehicle did not answer the station that answered its broadcast"
    finally:
        listener.close()
        assert daemon.stop() == 0
