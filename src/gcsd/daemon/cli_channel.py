"""``gcsd channel list|add|remove [-c FILE]``: a running daemon's channels, changed at run time
through its control socket (livechannels.py does the work; SPEC.md "Companion routing").

    gcsd channel list [-c FILE] [--json]
    gcsd channel add [-c FILE] NAME TYPE ADDRESS [--baud N]... [--option X]...   (serial: ADDRESS is the device)
    gcsd channel remove [-c FILE] NAME

The daemon is found as `gcsd status` finds it (control.py): FILE's state_dir socket, else the
daemon registered with FILE, else (no -c) the one registered daemon of this user. Exit codes:
0 done, 2 a channel the daemon refused (one line, the configuration's check without FILE:LINE)
or bad arguments, 1 no daemon answers.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from gcsd.api import control
from gcsd.config import CHANNEL_OPTIONS, CHANNEL_TYPES, ConfigError, default_config, load_config

EXIT_OK, EXIT_FAILURE, EXIT_BAD = 0, 1, 2


def add_parser(commands) -> None:
    channel = commands.add_parser("channel", help="list, add or remove a running daemon's channels")
    actions = channel.add_subparsers(dest="action", metavar="ACTION", required=True)
    helps = {"list": "the running channels", "remove": "close a channel",
             "add": "open a channel now (kept in state_dir/channels.yaml and restored at the next start)"}
    for name, text in helps.items():
        action = actions.add_parser(name, help=text)
        action.add_argument("-c", "--config", metavar="FILE", help="the running daemon's configuration")
        if name == "list":
            action.add_argument("--json", action="store_true", help="print the raw JSON")
        else:
            action.add_argument("name", metavar="NAME")
        if name == "add":
            action.add_argument("type", metavar="TYPE", choices=[t for t in CHANNEL_TYPES if t != "mqtt"],
                                help=" | ".join(t for t in CHANNEL_TYPES if t != "mqtt"))
            action.add_argument("address", metavar="ADDRESS", help="HOST:PORT, or the device of a serial channel")
            action.add_argument("--baud", type=int, action="append", metavar="N",
                                help="serial: a baud rate (again for a list tried in turn)")
            action.add_argument("--option", action="append", choices=CHANNEL_OPTIONS, metavar="X",
                                help=", ".join(CHANNEL_OPTIONS))


def run(args: argparse.Namespace) -> int:
    socket_path, problem = _find(args.config)
    if socket_path is None:
        print(f"gcsd channel: {problem}", file=sys.stderr)
        return EXIT_FAILURE
    try:
        return _act(args, socket_path)
    except (OSError, ValueError) as exc:  # ValueError: no JSON answer
        print(f"gcsd channel: the daemon at {socket_path} did not answer: {exc}", file=sys.stderr)
        return EXIT_FAILURE


def _act(args: argparse.Namespace, socket_path: Path) -> int:
    if args.action == "list":
        status = control.query(socket_path)
        print(json.dumps(status["channels"], indent=2) if args.json else control.format_channels(status))
        return EXIT_OK
    if args.action == "add":
        spec = {"name": args.name, "type": args.type}
        spec["device" if args.type == "serial" else "address"] = args.address
        if args.baud:
            spec["baud"] = args.baud[0] if len(args.baud) == 1 else args.baud
        if args.option:
            spec["options"] = args.option
        reply = control.request(socket_path, {"cmd": "channel_add", "spec": spec})
    else:
        reply = control.request(socket_path, {"cmd": "channel_remove", "name": args.name})
    if not reply.get("ok"):
        print(f"gcsd channel {args.action}: {reply.get('error')}", file=sys.stderr)
        return EXIT_BAD
    print(f"channel {args.name}: {'added' if args.action == 'add' else 'removed'}")
    return EXIT_OK


def _find(config_file: str | None) -> tuple[Path | None, str]:
    try:
        config = default_config() if config_file is None else load_config(config_file)
    except ConfigError as exc:
        return None, "; ".join(exc.problems)
    path = Path(config.state_dir) / control.SOCKET_NAME
    try:
        control.query(path)
        return path, ""
    except (OSError, ValueError):
        pass
    entries = [e for e in control.registered()
               if config_file is None or control.same_file(e.get("config"), config_file)]
    if len(entries) == 1:
        return Path(entries[0]["socket"]), ""
    if len(entries) > 1:
        return None, "several daemons are running: name one with -c FILE"
    return None, f"no daemon answers on {path}, and none is registered in {control.runtime_dir()}"
