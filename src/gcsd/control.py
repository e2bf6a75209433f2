"""The local control socket (`gcsd.sock` in state_dir, mode 0600) and `gcsd status`.

The daemon answers each connection with one JSON document: channels (type, address, peers,
counters, packet rates over the last statistics interval, signing rejects by reason), learned
routes and the vehicles. `gcsd status` prints it as tables. Read-only: nothing can be changed
through this socket.
"""

from __future__ import annotations

import asyncio
import json
import os
import socket
from pathlib import Path

SOCKET_NAME = "gcsd.sock"


async def serve(path: Path, snapshot) -> asyncio.AbstractServer:
    path.unlink(missing_ok=True)

    async def answer(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            writer.write(json.dumps(snapshot(), default=str).encode() + b"\n")
            await writer.drain()
        finally:
            writer.close()

    server = await asyncio.start_unix_server(answer, path=str(path))
    os.chmod(path, 0o600)
    return server


def query(path: Path, timeout_s: float = 3.0) -> dict:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as sock:
        sock.settimeout(timeout_s)
        sock.connect(str(path))
        chunks = []
        while True:
            data = sock.recv(65536)
            if not data:
                break
            chunks.append(data)
    return json.loads(b"".join(chunks))


def _table(headers: list[str], rows: list[list]) -> str:
    cells = [headers] + [[str(c) for c in row] for row in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(headers))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def format_status(status: dict) -> str:
    channels = [
        [c["name"], c["type"], c["address"], c["peers"], f'{c["rate_in"]:.0f}', f'{c["rate_out"]:.0f}',
         c["packets_in"], c["packets_out"], c["parse_errors"], c["crc_errors"], c["seq_gaps"], c["drops"],
         c["signature_rejects"]]
        for c in status["channels"]
    ]
    routes = [[r["sysid"], r["compid"], r["channel"], r["mavtype"], f'{r["age_s"]:.1f}'] for r in status["routes"]]
    vehicles = [[v["sysid"], v["compid"], v["type"], v["mode"], "yes" if v["armed"] else "no"] for v in status["vehicles"]]
    parts = [
        f'gcsd {status["version"]}, up {status["uptime_s"]:.0f} s',
        "",
        _table(["channel", "type", "address", "peers", "in/s", "out/s", "in", "out", "parse_err",
                "crc_err", "seq_gaps", "drops", "sig_rejects"], channels),
        "",
        _table(["sysid", "compid", "channel", "mavtype", "seen_s_ago"], routes) if routes else "no routes learned",
        "",
        _table(["sysid", "compid", "vehicle", "mode", "armed"], vehicles),
    ]
    rejects = {c["name"]: c["signature_reject_reasons"] for c in status["channels"] if c["signature_reject_reasons"]}
    if rejects:
        parts += ["", "signature rejects: " + "; ".join(f"{n}: {r}" for n, r in rejects.items())]
    return "\n".join(parts)
