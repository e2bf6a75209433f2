"""The local control socket (`gcsd.sock` in state_dir, mode 0600), its registration, and the
tables `gcsd status` prints.

Each connection carries one request, a JSON line, and gets one JSON document back:
- `{"cmd": "status"}` (or nothing: the connection is half-closed or silent for REQUEST_WAIT_S):
  channels (type, address, peers, counters, packet rates over the last statistics interval,
  signing rejects by reason), learned routes, the vehicles, the per-component error counts
  (`errors`) and the counted events outside the channels (`counters`: routing's drops, each
  service's, summed over a swarm).
- `{"cmd": "channel_add", "spec": {...}}` and `{"cmd": "channel_remove", "name": ...}`
  (`gcsd channel add|remove`, livechannels.py): `{"ok": true}` or `{"ok": false, "error": ...}`.
The socket is the daemon's user's alone (created under a umask of 077, then 0600, in state_dir:
never a moment open to others): whoever can open it may change the channels, as whoever can send
the daemon SIGHUP may reload them.

Finding a daemon (the rule `gcsd status` follows; relative paths in a configuration are relative
to the daemon's working directory, so the socket's path depends on where it was started):

1. Once it is ready (servers bound, clients tried), a daemon registers: `<pid>.json` in its runtime directory,
   `$XDG_RUNTIME_DIR/gcsd/` or, without that variable, `/tmp/gcsd-<uid>/` (created 0700; a
   directory not owned by the user or open to others is ignored). The entry holds the
   absolute socket path, the absolute configuration file (null for the built-in default),
   the state directory and the pid. It is removed at the stop; entries of dead processes are
   ignored and cleaned up by the next `gcsd status`.
2. `gcsd status -c FILE`: FILE's state_dir/gcsd.sock as seen from here, if a daemon answers
   there; else the registered daemon that was started with that same FILE.
3. `gcsd status`: ./gcsd-state/gcsd.sock (the default configuration, run here), if a daemon
   answers; else every registered daemon of this user (each one's tables, in pid order).

Under systemd (`PrivateTmp`, no `XDG_RUNTIME_DIR`) the registration is private to the unit:
use `gcsd status -c /etc/gcsd/gcsd.yaml`, whose state_dir is absolute (systemd/README.md).
"""

from __future__ import annotations

import asyncio
import errno
import json
import os
import socket
import stat
import tempfile
from dataclasses import dataclass
from pathlib import Path

from gcsd.atomic import write_atomic

SOCKET_NAME = "gcsd.sock"
REQUEST_WAIT_S = 2.0
_MAV_TYPE_PREFIX = "MAV_TYPE_"


async def serve(path: Path, snapshot, commands: dict | None = None, on_error=None) -> asyncio.AbstractServer:
    """`snapshot()` answers status; `commands[name](request)` (a coroutine returning None or an
    error line) answers the others. A command that raises is answered as failed and reported to
    `on_error()` (the daemon's ErrorCounts), never left without an answer."""
    if _answers(path):  # another daemon's: never taken over (its `gcsd status` would go dark)
        raise OSError(errno.EADDRINUSE, f"another daemon answers on {path}")
    path.unlink(missing_ok=True)  # left behind by a daemon that was killed
    commands = commands or {}

    async def answer(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            request = await _request(reader)
            handler = commands.get(request.get("cmd"))
            if request.get("cmd", "status") == "status":
                reply = snapshot()
            elif handler is None:
                reply = {"ok": False, "error": f"unknown request {request.get('cmd')!r}"}
            else:
                try:
                    error = await handler(request)
                except Exception:  # noqa: BLE001  (a failed request is answered, never ends the server)
                    if on_error is not None:
                        on_error(request.get("cmd"))
                    error = "the daemon failed to do it (its log has the traceback)"
                reply = {"ok": error is None, "error": error}
            writer.write(json.dumps(reply, default=str).encode() + b"\n")
            await writer.drain()
        finally:
            writer.close()

    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        bind_private(sock, path)
        return await asyncio.start_unix_server(answer, sock=sock)
    except BaseException:
        sock.close()
        raise


def bind_private(sock: socket.socket, path: Path) -> None:
    """Bind a Unix socket that is the user's alone from the instant it exists: created under a
    umask of 077 (a socket's mode is 0777 minus the umask), then 0600. The umask is the
    process's, so it is set and put back around the bind alone, a few microseconds."""
    old = os.umask(0o077)
    try:
        sock.bind(str(path))
    finally:
        os.umask(old)
    os.chmod(path, 0o600)


async def _request(reader: asyncio.StreamReader) -> dict:
    try:
        line = await asyncio.wait_for(reader.readline(), REQUEST_WAIT_S)
    except (TimeoutError, ValueError):  # ValueError: a line over the stream's limit
        return {}
    try:
        request = json.loads(line) if line.strip() else {}
    except ValueError:
        return {"cmd": "invalid"}
    return request if isinstance(request, dict) else {"cmd": "invalid"}


def _answers(path: Path) -> bool:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(1.0)
        try:
            sock.connect(str(path))
        except OSError:  # absent, refused (nobody listening), not a socket
            return False
    return True


def query(path: Path, timeout_s: float = 3.0) -> dict:
    document = request(path, {"cmd": "status"}, timeout_s)
    if not isinstance(document, dict) or not isinstance(document.get("channels"), list):
        # a wrong answer, not a wrong argument: callers catch ValueError, as for an answer that is no JSON
        raise ValueError("the answer is not a gcsd status document")  # noqa: TRY004
    return document


def request(path: Path, message: dict, timeout_s: float = 15.0):
    """One request to a daemon's control socket; its JSON answer."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(timeout_s)
        sock.connect(str(path))
        sock.sendall(json.dumps(message).encode() + b"\n")
        chunks = []
        while True:
            data = sock.recv(65536)
            if not data:
                break
            chunks.append(data)
    return json.loads(b"".join(chunks))


# --- registration: how `gcsd status` finds a daemon started elsewhere -------------------------


def runtime_dir() -> Path:
    base = os.environ.get("XDG_RUNTIME_DIR")
    return Path(base) / "gcsd" if base else Path(tempfile.gettempdir()) / f"gcsd-{os.getuid()}"


def _private_dir(path: Path, create: bool) -> bool:
    """The runtime directory exists (created if asked), is ours and is closed to others."""
    try:
        if create:
            path.mkdir(mode=0o700, parents=True, exist_ok=True)
        info = path.lstat()
    except OSError:
        return False
    return stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid() and not info.st_mode & 0o077


@dataclass(frozen=True)
class Registration:
    path: Path | None

    def remove(self) -> None:
        if self.path is not None:
            self.path.unlink(missing_ok=True)


def register(config) -> Registration:
    """Publish this daemon's control socket; never fails the daemon (returns an empty
    registration when the runtime directory cannot be used)."""
    directory = runtime_dir()
    if not _private_dir(directory, create=True):
        return Registration(None)
    entry = {
        "pid": os.getpid(),
        "socket": str((Path(config.state_dir) / SOCKET_NAME).absolute()),
        "state_dir": str(Path(config.state_dir).absolute()),
        "config": None if config.source.file is None else str(Path(config.source.file).absolute()),
    }
    path = directory / f"{os.getpid()}.json"
    try:
        write_atomic(path, json.dumps(entry) + "\n", mode=0o600)
    except OSError:
        return Registration(None)
    return Registration(path)


def registered() -> list[dict]:
    """The registered daemons of this user that are still running, in pid order."""
    directory = runtime_dir()
    if not _private_dir(directory, create=False):
        return []
    found = []
    for path in sorted(directory.glob("*.json"), key=lambda p: p.stem.zfill(12)):
        try:
            entry = json.loads(path.read_text())
            pid = int(entry["pid"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if not _alive(pid):
            path.unlink(missing_ok=True)
            continue
        found.append(entry)
    return found


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def same_file(a: str | None, b: str | os.PathLike) -> bool:
    try:
        return a is not None and os.path.samefile(a, b)
    except OSError:
        return False


# --- the tables -------------------------------------------------------------------------------


# counters of what a peer or a broker sent that was dropped on purpose (issue 17), as table columns
_DROP_COLUMNS = (("spoofed_dropped", "spoofed"), ("retained_dropped", "retained"), ("loop_dropped", "loop"),
                 ("unauthenticated_closed", "unauth closed"), ("accept_failures", "accept failed"))


def _table(title: str, headers: list[str], rows: list[list]) -> str:
    if not rows:
        return f"{title}: none"
    cells = [headers] + [[str(c) for c in row] for row in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join([title, *lines])


def mav_type_name(mav_type) -> str:
    """HEARTBEAT.type as a word (QUADROTOR, GCS, FIXED_WING...); '-' before any heartbeat."""
    if mav_type is None:
        return "-"
    from pymavlink.dialects.v20 import ardupilotmega as M  # only `gcsd status` needs it

    entry = M.enums["MAV_TYPE"].get(int(mav_type))
    return entry.name.removeprefix(_MAV_TYPE_PREFIX) if entry is not None else str(mav_type)


def _duration(seconds: float) -> str:
    seconds = int(seconds)
    if seconds < 60:
        return f"{seconds} s"
    minutes, s = divmod(seconds, 60)
    if minutes < 60:
        return f"{minutes} min {s} s"
    hours, m = divmod(minutes, 60)
    return f"{hours} h {m} min"


def format_channels(status: dict) -> str:
    """The Channels table of `gcsd status` (also `gcsd channel list`)."""
    channels = [
        [c["name"], c["type"], c.get("address", ""), c.get("peers", 0), f'{c.get("rate_in", 0):.0f}',
         f'{c.get("rate_out", 0):.0f}', c.get("packets_in", 0), c.get("packets_out", 0), c.get("bytes_in", 0),
         c.get("bytes_out", 0)]
        for c in status.get("channels", [])
    ]
    return _table("Channels", ["channel", "type", "address", "peers", "in (pkt/s)", "out (pkt/s)", "in (pkt)",
                               "out (pkt)", "in (B)", "out (B)"], channels)


def _http_line(http: dict | None) -> str:
    """Where the API listens, read-only or not, its connections and its refusals by reason."""
    if http is None:
        return "HTTP API: off"
    if http.get("listening"):
        line = f'HTTP API: listening on {http["listening"]}'
        if http.get("read_only"):
            line += " (read-only: signing.require and no token)"
        if "connections" in http:
            line += f', {http["connections"]} of {http.get("max_connections", "?")} connections'
    else:
        line = f'HTTP API: not listening on {http.get("address")} ({http.get("error") or "starting"}; retrying)'
    refused = http.get("refused") or {}
    if refused:
        line += "; http_refused " + ", ".join(f"{reason} {n}" for reason, n in sorted(refused.items()))
    return line


def format_status(status: dict, daemon: dict | None = None) -> str:
    """The status document as titled tables; units in the headers (pkt/s, B, s)."""
    chans = status.get("channels", [])
    problems = [
        [c["name"], c.get("parse_errors", 0), c.get("crc_errors", 0), c.get("unknown_ids", 0), c.get("seq_gaps", 0),
         c.get("drops", 0), c.get("signature_rejects", 0), c.get("peers_forgotten", 0), c.get("peers_replaced", 0),
         c.get("filtered_in", 0), c.get("filtered_out", 0), c.get("rate_limited", 0), c.get("duplicates", 0),
         c.get("muted", 0), c.get("open_failures", 0), *(c.get(key, 0) for key, _ in _DROP_COLUMNS)]
        for c in chans
    ]
    routes = [[r["sysid"], r["compid"], mav_type_name(r.get("mavtype")), r["channel"], f'{r["age_s"]:.1f}']
              for r in status.get("routes", [])]
    vehicles = [[v["sysid"], v["compid"], v["type"], v["mode"], "yes" if v["armed"] else "no"]
                for v in status.get("vehicles", [])]
    errors = [[name, count] for name, count in sorted(status.get("errors", {}).items())]
    counters = [[name, count] for name, count in sorted(status.get("counters", {}).items())]
    head = f'gcsd {status.get("version", "?")}, up {_duration(status.get("uptime_s", 0))}'
    if daemon is not None:
        head += f' (pid {daemon.get("pid")}, config {daemon.get("config") or "built-in default"})'
    parts = [
        head,
        _http_line(status.get("http")),
        "",
        format_channels(status),
        "",
        _table("Channel errors and drops (counts)", ["channel", "parse", "bad CRC", "unknown id", "seq gaps",
                                                     "drops", "signing rejects", "peers expired",
                                                     "peers replaced", "filtered in", "filtered out",
                                                     "rate limited", "duplicates", "muted", "open failures",
                                                     *(h for _, h in _DROP_COLUMNS)],
               problems),
        "",
        _table("Routes learned", ["sysid", "compid", "MAV_TYPE", "via channel", "last heard (s ago)"], routes),
        "",
        _table("Vehicles", ["sysid", "compid", "vehicle", "mode", "armed"], vehicles),
        "",
        _table("Errors (exceptions caught, by component)", ["component", "count"], errors),
        "",
        _table("Counters (routing, vehicles' services)", ["counter", "count"], counters),
    ]
    rejects = {c["name"]: c["signature_reject_reasons"] for c in chans if c.get("signature_reject_reasons")}
    if rejects:
        parts += ["", "Signing rejects by reason: " + "; ".join(
            f"{n}: " + ", ".join(f"{k} {v}" for k, v in sorted(r.items())) for n, r in rejects.items())]
    return "\n".join(parts)
