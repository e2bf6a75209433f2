"""The compiled fast path (gcsd.wire._speedups, C) and the pure-Python code it stands in for.

What a routed datagram costs is mostly interpreter work per packet (issue 19; bench/RESULTS.md):
one Python-level `recvfrom` per datagram and one more that raises at the end of each drain, and
the byte loop of the frame parser; one `sendto` per datagram, whose address is parsed again
each time. The C module does those things:

- `recv_batch(sock, n)`: up to n waiting datagrams of a UDP socket, as [(bytes, (host, port))],
  in one `recvmmsg(2)`; [] when none waits. An error on the first datagram (an ICMP port
  unreachable from an earlier send, say) raises OSError; one after it is left for the next call.
- `send_batch(sock, items)`: [(bytes, (host, port))] sent in one `sendmmsg(2)`; returns how many
  were sent: a datagram that meets a full buffer or an error is dropped, the rest go on.
- `feed(parser, data)`: codec.FrameParser.feed (codec.feed_python is its reference).

It is optional: `setup.py` builds it when a C compiler is there (`optional=True`) and gcsd runs
the same code in Python when it is not, or when GCSD_PURE_PYTHON is set (to compare, or to rule
it out). `IMPLEMENTATION` says which one runs; `gcsd --version` and `gcsd status --json` show it. Both are tested
against each other (tests/unit/test_speedups.py, tests/unit/test_codec.py). The compiled
recv_batch and send_batch take IPv4 sockets only; an IPv6 socket gets the Python ones.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Callable

try:
    if os.environ.get("GCSD_PURE_PYTHON"):
        raise ImportError("GCSD_PURE_PYTHON is set")
    from gcsd.wire import _speedups as compiled
except ImportError:
    compiled = None

IMPLEMENTATION = "c" if compiled is not None else "python"
DESCRIPTION = "compiled packet path" if compiled is not None else "pure-Python packet path"  # gcsd --version
MAX_DATAGRAM = 65536


def recv_batch_python(sock: socket.socket, n: int) -> list[tuple[bytes, tuple]]:
    out: list[tuple[bytes, tuple]] = []
    recvfrom = sock.recvfrom
    for _ in range(n):
        try:
            out.append(recvfrom(MAX_DATAGRAM))
        except (BlockingIOError, InterruptedError):
            break
        except OSError:
            if not out:
                raise
            break
    return out


def send_batch_python(sock: socket.socket, items: list[tuple[bytes, tuple]]) -> int:
    sent = 0
    sendto = sock.sendto
    for data, addr in items:
        try:
            sendto(data, addr)
        except OSError:  # a full buffer (EAGAIN), unreachable, closed: this one is dropped
            continue
        sent += 1
    return sent


def sender(sock: socket.socket) -> Callable[[socket.socket, list[tuple[bytes, tuple]]], int]:
    """The send_batch for this socket: the compiled one for IPv4, else the Python one."""
    if compiled is not None and sock.family == socket.AF_INET:
        return compiled.send_batch
    return send_batch_python


def receiver(sock: socket.socket) -> Callable[[socket.socket, int], list[tuple[bytes, tuple]]]:
    """The recv_batch for this socket: the compiled one for IPv4, else the Python one."""
    if compiled is not None and sock.family == socket.AF_INET:
        return compiled.recv_batch
    return recv_batch_python


def compiled_feed(frame_type: type, infos: dict[int, tuple[int, int, int]]):
    """The compiled FrameParser.feed, set up with the Frame class and the dialect's table
    {msgid: (crc_extra, target_system_ofs, target_component_ofs)}; None without the module."""
    if compiled is None:
        return None
    compiled.setup(frame_type, infos)
    return compiled.feed
