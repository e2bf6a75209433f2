"""The command line: ``gcsd [run] [-c FILE]``, ``gcsd -c FILE``, ``gcsd check-config FILE``,
``gcsd status [-c FILE] [--json]``, ``gcsd logs [-c FILE] [--json]``,
``gcsd channel list|add|remove [-c FILE]`` (cli_channel.py), ``gcsd --version``.

`main` returns the exit code (the console script does ``sys.exit(main())``): 0 a clean stop or a
good configuration, 2 a bad configuration or bad arguments, 1 any other failure. A bad
configuration is reported as one ``FILE:LINE: key.path: what is wrong`` line per problem on
stderr, and starts nothing. check-config checks the text (config.py) and, without changing
anything, what the daemon will need on disk (preflight.check: state_dir, params_file, tlog);
`run` creates what it needs first (preflight.prepare, in app.py) and refuses to start with the
same lines. Each subcommand is one ``_<name>(args) -> int`` function in `_COMMANDS`.

``-c FILE`` before the command (``gcsd -c FILE``, as the sitl/ headers write it) is the same as
after it: ``gcsd -c FILE`` runs FILE, ``gcsd -c FILE status`` asks FILE's daemon.
`gcsd status` finds a daemon by the rule in control.py (state_dir's socket, else the daemon
registered with the same configuration file, else every registered daemon of this user).
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys

import structlog

from gcsd import __version__
from gcsd.config import ConfigError, default_config, load_config
from gcsd.daemon import cli_channel
from gcsd.log import setup_logging
from gcsd.loop import loop_name
from gcsd.wire import speedups

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_BAD_CONFIG = 2  # also argparse's code for bad arguments


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help and --version (0), bad arguments (2)
        return exc.code if isinstance(exc.code, int) else EXIT_OK
    top_config = getattr(args, "top_config", None)
    if top_config is not None and getattr(args, "config", None) is None:
        args.config = top_config
    if args.command == "check-config" and top_config is not None:
        print("gcsd: check-config takes the file as its argument: gcsd check-config FILE", file=sys.stderr)
        return EXIT_BAD_CONFIG
    return _COMMANDS[args.command or "run"](args)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="gcsd", description="The vehicle side of MAVLink: a simulated or embedded vehicle that "
                                 "ground stations connect to. With no command: run.")
    parser.add_argument("--version", action="version", version=f"gcsd {__version__} ({loop_name()}, {speedups.DESCRIPTION})")
    parser.add_argument("-c", "--config", metavar="FILE", dest="top_config",
                        help="configuration file; `gcsd -c FILE` is `gcsd run -c FILE`")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    run = commands.add_parser("run", help="run in the foreground (the default command)")
    run.add_argument("-c", "--config", metavar="FILE",
                     help="configuration file (default: the built-in default, as config/gcsd.yaml)")
    check = commands.add_parser("check-config", help="validate a configuration file and exit")
    check.add_argument("file", metavar="FILE")
    status = commands.add_parser("status", help="show a running daemon's channels, routes and counters")
    status.add_argument("-c", "--config", metavar="FILE",
                        help="the running daemon's configuration (its state_dir holds the socket; a daemon "
                             "started from another directory with the same file is found through its "
                             "registration)")
    status.add_argument("--json", action="store_true", help="print the raw JSON")
    logs = commands.add_parser("logs", help="list the flight logs (DataFlash .BIN) a configuration keeps")
    logs.add_argument("-c", "--config", metavar="FILE", help="configuration file (default: the built-in default)")
    logs.add_argument("--json", action="store_true", help="print JSON")
    cli_channel.add_parser(commands)
    return parser


def _run(args: argparse.Namespace) -> int:
    # SIGHUP's default action ends the process: ignored from here until the daemon installs its
    # own handler (app.py), so a reload that comes early never kills a starting daemon
    with contextlib.suppress(ValueError):  # not the main thread: signals are not ours to set
        signal.signal(signal.SIGHUP, signal.SIG_IGN)
    config_file = getattr(args, "config", None)
    try:
        config = default_config() if config_file is None else load_config(config_file)
    except ConfigError as exc:
        _print_problems(exc)
        return EXIT_BAD_CONFIG
    setup_logging(config.log.level, config.log.format)
    log = structlog.get_logger("gcsd.daemon.cli")
    try:
        from gcsd import loop
        from gcsd.daemon.app import run_daemon  # here, so that check-config needs nothing of the daemon

        return loop.run(run_daemon(config))
    except KeyboardInterrupt:  # the daemon handles SIGINT itself; this is a stop it did not see
        log.warning("daemon_interrupted")
        return EXIT_FAILURE
    except Exception:
        log.exception("daemon_failed")
        return EXIT_FAILURE


def _check_config(args: argparse.Namespace) -> int:
    from gcsd.config import preflight

    try:
        config = load_config(args.file)
    except ConfigError as exc:
        _print_problems(exc)
        return EXIT_BAD_CONFIG
    problems = preflight.check(config)
    if problems:
        _print_problems(ConfigError(problems))
        return EXIT_BAD_CONFIG
    print(f"{args.file}: ok")
    return EXIT_OK


def _config_of(args: argparse.Namespace):
    """`-c FILE`'s configuration (the built-in default without it), or None with its problems printed."""
    try:
        return default_config() if args.config is None else load_config(args.config)
    except ConfigError as exc:
        _print_problems(exc)
        return None


def _print_problems(error: ConfigError) -> None:
    for problem in error.problems:
        print(problem, file=sys.stderr)


def _status(args: argparse.Namespace) -> int:
    import json
    from pathlib import Path

    from gcsd.api import control

    config = _config_of(args)
    if config is None:
        return EXIT_BAD_CONFIG
    path = Path(config.state_dir) / control.SOCKET_NAME
    try:
        answers = [(None, control.query(path))]
    except (OSError, ValueError) as exc:  # ValueError: something else answers there, not gcsd's JSON
        local_error = exc
        answers = []
    if not answers:  # started from another directory? ask the registered daemons
        for entry in control.registered():
            if args.config is not None and not control.same_file(entry.get("config"), args.config):
                continue
            try:
                answers.append((entry, control.query(Path(entry["socket"]))))
            except (OSError, ValueError, KeyError, TypeError):
                continue
    if not answers:
        which = "" if args.config is None else f" started with {args.config}"
        reason = getattr(local_error, "strerror", None) or local_error
        print(f"gcsd status: no daemon answers on {path} ({reason}), and no "
              f"daemon{which} is registered in {control.runtime_dir()}", file=sys.stderr)
        return EXIT_FAILURE
    if args.json:
        documents = [status for _, status in answers]
        print(json.dumps(documents[0] if len(documents) == 1 else documents, indent=2))
    else:
        print("\n\n".join(control.format_status(status, entry) for entry, status in answers))
    return EXIT_OK


def _logs(args: argparse.Namespace) -> int:
    import json

    from gcsd.payloads.logs.listing import format_logs, list_logs

    config = _config_of(args)
    if config is None:
        return EXIT_BAD_CONFIG
    logs = list_logs(config)
    print(json.dumps(logs, indent=2) if args.json else format_logs(logs, config))
    return EXIT_OK


def _channel(args: argparse.Namespace) -> int:
    return cli_channel.run(args)


_COMMANDS = {"run": _run, "check-config": _check_config, "status": _status, "logs": _logs, "channel": _channel}
