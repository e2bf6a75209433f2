"""Checks of a configuration against the filesystem, before anything starts.

config.py validates the text alone; what depends on the machine is checked here and reported
the same way, ``FILE:LINE: key.path: what is wrong`` (the line comes from `Config.source`):

- state_dir (and each swarm vehicle's `vehicle-N` under it) must be a directory the daemon can
  create and write: a path through a file, a read-only place or a missing permission is a
  problem, found before a single socket is opened, not as a traceback half-way through.
- The FTP root of each vehicle (`ftp.root` under its state directory) must be a directory and,
  symlinks resolved, must not be the state directory or contain it: FTP clients would read
  `signing.key` and `mav.parm` (config.py already refuses "." in the text).
- params_file must be readable, and every line good against the vehicle's real parameter set
  (services/params.params_file_problems, the very check the daemon makes when it loads it).
- In a swarm (vehicle.count > 1) params_file may not set SYSID_THISMAV: every vehicle would take
  the same sysid; the swarm's sysids come from vehicle.sysid.
- log.tlog must name a writable file in a directory that can be created.
- The flight-log directory (`flight_logs.dir` under each vehicle's state directory) must be a
  directory the daemon can create and write (a file in its place is a problem).
- http.token_file, when the API is on, must be readable with a token on its first line.

`check(config)` only looks (check-config: it must not create anything, and runs as the same
user as the daemon under systemd's ExecStartPre); `prepare(config)` also creates the
directories and proves state_dir writable with a probe file, as `gcsd run` needs.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from gcsd.config import Config
from gcsd.config.authority import read_key
from gcsd.config.http import read_token


def check(config: Config) -> list[str]:
    """Problems found without changing anything on disk."""
    problems = [*_state_dir_can_be_made(config), *_params_file(config)]
    if not problems:
        problems += _dir_can_be_made(config, "flight_logs.dir", Path(config.state_dir) / config.flight_logs.dir)
    if config.params_file is not None and not problems:
        problems += _params_file_content(config) or _swarm_sysid(config)
    if config.log.tlog:
        problems += _parent_can_be_made(config, "log.tlog", Path(config.log.tlog))
    return problems + _token_file(config) + _key_files(config)


def _key_files(config: Config) -> list[str]:
    """signing.keys and http.tokens: each file readable, with a key / passphrase / token."""
    problems = []
    for i, named in enumerate(config.signing.keys):
        which = "key_file" if named.key_file is not None else "passphrase_file"
        try:
            read_key(named, Path)
        except (OSError, ValueError) as exc:
            why = getattr(exc, "strerror", None) or exc
            problems.append(f"{config.source.where(f'signing.keys[{i}].{which}')}: cannot read "
                            f"{getattr(named, which)}: {why}")
    for i, token in enumerate(config.http.tokens if config.http.address is not None else ()):
        try:
            read_token(token.token_file)
        except (OSError, ValueError) as exc:
            why = getattr(exc, "strerror", None) or exc
            problems.append(f"{config.source.where(f'http.tokens[{i}].token_file')}: cannot read a token "
                            f"from {token.token_file}: {why}")
    return problems


def _token_file(config: Config) -> list[str]:
    http = config.http
    if http.address is None or http.token_file is None:
        return []
    try:
        read_token(http.token_file)
    except (OSError, ValueError) as exc:
        why = getattr(exc, "strerror", None) or exc
        return [f"{config.source.where('http.token_file')}: cannot read a token from {http.token_file}: {why}"]
    return []


def prepare(config: Config) -> list[str]:
    """Create state_dir, the vehicle directories, the FTP roots and the flight-log directories;
    problems if that fails."""
    problems = _params_file(config) + _token_file(config) + _key_files(config)
    if config.params_file is not None and not problems:
        problems += _swarm_sysid(config)
    if config.log.tlog:
        problems += _parent_can_be_made(config, "log.tlog", Path(config.log.tlog))
    where = config.source.where("state_dir")
    state_dir = Path(config.state_dir)
    try:
        state_dir.mkdir(parents=True, exist_ok=True)
        _probe_write(state_dir)
        vehicle_dirs = [state_dir] if config.vehicle.count == 1 else [
            state_dir / f"vehicle-{i + 1}" for i in range(config.vehicle.count)]
        for vehicle_dir in vehicle_dirs:
            vehicle_dir.mkdir(exist_ok=True)
    except OSError as exc:
        what = f"cannot use {_show(exc.filename or state_dir)} as the state directory: {exc.strerror or exc}"
        return [*problems, f"{where}: {what}"]
    return problems + (_ftp_roots(config, state_dir, vehicle_dirs) or _log_dirs(config, vehicle_dirs))


def _log_dirs(config: Config, vehicle_dirs: list[Path]) -> list[str]:
    """Each vehicle's flight-log directory (`flight_logs.dir` under its state directory)."""
    for vehicle_dir in vehicle_dirs:
        directory = vehicle_dir / config.flight_logs.dir
        try:
            directory.mkdir(parents=True, exist_ok=True)
            _probe_write(directory)
        except OSError as exc:
            what = f"cannot use {_show(exc.filename or directory)} for flight logs: {exc.strerror or exc}"
            return [f"{config.source.where('flight_logs.dir')}: {what}"]
    return []


def _ftp_roots(config: Config, state_dir: Path, vehicle_dirs: list[Path]) -> list[str]:
    where = config.source.where("ftp.root")
    for vehicle_dir in vehicle_dirs:
        root = vehicle_dir / config.ftp.root
        try:
            root.mkdir(parents=True, exist_ok=True)
            resolved = root.resolve(strict=True)
            protected = {state_dir.resolve(strict=True), vehicle_dir.resolve(strict=True)}
        except OSError as exc:
            return [f"{where}: cannot use {_show(exc.filename or root)} as the FTP root: {exc.strerror or exc}"]
        for directory in protected:
            if directory == resolved or directory.is_relative_to(resolved):
                what = (f"{_show(root)} resolves to {_show(resolved)}, which holds the state directory "
                        f"{_show(directory)}: FTP clients could read the signing key and the saved parameters")
                return [f"{where}: {what}"]
    return []


def _state_dir_can_be_made(config: Config) -> list[str]:
    return _dir_can_be_made(config, "state_dir", Path(config.state_dir))


def _parent_can_be_made(config: Config, key: str, path: Path) -> list[str]:
    try:
        return _parent_checks(config, key, path)
    except OSError as exc:  # stat refused (a directory we may not search)
        return [f"{config.source.where(key)}: cannot check {_show(path)}: {exc.strerror or exc}"]


def _parent_checks(config: Config, key: str, path: Path) -> list[str]:
    if path.is_dir():
        return [f"{config.source.where(key)}: {_show(path)} is a directory"]
    if path.exists() and not os.access(path, os.W_OK):
        return [f"{config.source.where(key)}: {_show(path)} is not writable"]
    return _dir_can_be_made(config, key, path.parent)


def _dir_can_be_made(config: Config, key: str, path: Path) -> list[str]:
    """The directory exists and is writable, or its nearest existing ancestor is a writable
    directory (so mkdir will work)."""
    where = config.source.where(key)
    existing = path
    try:
        while not existing.exists() and existing != existing.parent:
            existing = existing.parent
    except OSError as exc:  # stat refused (a directory we may not search)
        return [f"{where}: cannot create or write {_show(path)}: {exc.strerror or exc}"]
    if not existing.is_dir():
        return [f"{where}: cannot create {_show(path)}: {_show(existing)} is not a directory"]
    if not os.access(existing, os.W_OK | os.X_OK):
        return [f"{where}: cannot create or write {_show(path)}: {_show(existing)} is not writable"]
    return []


def _params_file(config: Config) -> list[str]:
    path = config.params_file
    if path is None:
        return []
    try:
        with open(path, "rb"):
            pass
    except OSError as exc:
        return [f"{config.source.where('params_file')}: cannot read {_show(path)}: {exc.strerror or exc}"]
    return []


def vehicle_param_store(config: Config, index: int = 0):
    """The parameter store vehicle `index` of this configuration starts from (its defaults)."""
    from gcsd.vehicle.params import ParamStore
    from gcsd.vehicle.types import vehicle_params, vehicle_type

    v = config.vehicle
    return ParamStore(vehicle_params(vehicle_type(v.type), v.sysid + index, config.gcs.sysid, config.gcs.enforce_sysid,
                                     [dict(ch.streams) for ch in config.channels], v.speedup))


def _params_file_content(config: Config) -> list[str]:
    """Every line of params_file checked against the vehicle's real parameter set (the same
    check the daemon makes at start, services/params.py)."""
    from gcsd.vehicle.services.params import params_file_problems

    return params_file_problems(vehicle_param_store(config), Path(config.params_file))


def _swarm_sysid(config: Config) -> list[str]:
    from gcsd.vehicle.params.parmfile import read_parm_lines

    if config.vehicle.count == 1:
        return []
    try:
        lines, _ = read_parm_lines(Path(config.params_file))
    except OSError:
        return []  # reported by _params_file
    return [f"{_show(config.params_file)}:{p.line}: SYSID_THISMAV: would give all {config.vehicle.count} vehicles "
            f"of the swarm one sysid; their sysids come from vehicle.sysid" for p in lines if p.name == "SYSID_THISMAV"]


def _probe_write(directory: Path) -> None:
    """Prove the directory writable (root passes os.access on a read-only filesystem)."""
    fd, name = tempfile.mkstemp(prefix=".gcsd-probe-", dir=directory)
    os.close(fd)
    os.unlink(name)


def _show(path) -> str:
    return os.fsdecode(path)
