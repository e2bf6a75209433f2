"""A tcp-server channel's listening socket: its accept loop and the process's descriptor budget.

Accept loop (`Listener`): on readiness, accept up to ACCEPT_BATCH connections; each becomes a
transport and a `_Stream` protocol (transport.py) through `loop.connect_accepted_socket`.
States: listening -> paused -> listening. When accept() fails for lack of resources (EMFILE,
ENFILE: out of descriptors; ENOBUFS, ENOMEM) the listening socket stays readable, so it is
taken out of the loop for ACCEPT_PAUSE_S and then watched again: never a hot loop. Each failure
is counted (`accept_failures`, `gcsd status`); the log says so at most once per
ACCEPT_LOG_INTERVAL_S per channel, with the count since the last line, never a traceback per
attempt. A connection reset before it was accepted (ECONNABORTED) is skipped.

Descriptor budget: a tcp-server channel holds at most max_peers + 1 connections (unauth.py)
and the HTTP API at most its MAX_CONNECTIONS (gcsd.api.http.service), so the process needs at
most `descriptors_needed(channels, http_connections)`: those and their listeners, plus FD_RESERVE for
everything else (the control socket and the connections `gcsd status` makes, state files,
UDP, serial and MQTT sockets, log and tlog files, worker threads' wake-up pipes).
`ensure_descriptor_budget` raises the soft RLIMIT_NOFILE to that when it is lower (up to the
hard limit; systemd gives services 1 024 soft and 524 288 hard) and reports what it got, so the
control socket always finds a descriptor whatever the ground stations do.
"""

from __future__ import annotations

import asyncio
import errno
import functools
import resource
import socket
from collections.abc import Callable, Iterable

import structlog

log = structlog.get_logger("gcsd.links.tcpserver")

ACCEPT_BATCH = 64
ACCEPT_PAUSE_S = 1.0
ACCEPT_LOG_INTERVAL_S = 10.0
FD_RESERVE = 64
_OUT_OF_RESOURCES = (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM)


class Listener:
    """One listening socket; `close()` stops accepting (connections already made are the channel's)."""

    def __init__(self, channel, sock: socket.socket, protocol_factory: Callable[[], asyncio.Protocol],
                 pause_s: float = ACCEPT_PAUSE_S) -> None:
        self.channel = channel
        self.pause_s = pause_s
        self.sock = sock
        self.factory = protocol_factory
        self.loop = asyncio.get_running_loop()
        self._connecting: set[asyncio.Task] = set()
        self._resume: asyncio.TimerHandle | None = None
        self._logged_s: float | None = None
        self._unlogged = 0
        sock.setblocking(False)
        self.loop.add_reader(sock.fileno(), self._accept_ready)

    def _accept_ready(self) -> None:
        for _ in range(ACCEPT_BATCH):
            try:
                conn, _addr = self.sock.accept()
            except (BlockingIOError, InterruptedError):
                return
            except ConnectionAbortedError:
                continue
            except OSError as exc:
                if exc.errno not in _OUT_OF_RESOURCES:
                    raise
                self._failed(exc)
                return
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            task = self.loop.create_task(self.loop.connect_accepted_socket(self.factory, conn))
            self._connecting.add(task)
            task.add_done_callback(functools.partial(self._connected, conn))

    def _connected(self, conn: socket.socket, task: asyncio.Task) -> None:
        self._connecting.discard(task)
        if task.cancelled():  # closed before its transport took the socket (a second close is harmless)
            conn.close()
        elif task.exception() is not None:
            conn.close()
            log.warning("connection_setup_failed", channel=self.channel.name, error=str(task.exception()))

    def _failed(self, exc: OSError) -> None:
        """Out of resources: count, log at most once per interval, pause accepting."""
        self.channel.stats.accept_failures += 1
        now = self.channel.clock()
        if self._logged_s is None or now - self._logged_s >= ACCEPT_LOG_INTERVAL_S:
            log.error("accept_failed", channel=self.channel.name, error=exc.strerror or str(exc),
                      not_logged_since_last=self._unlogged, pause_s=self.pause_s)
            self._logged_s, self._unlogged = now, 0
        else:
            self._unlogged += 1
        self.loop.remove_reader(self.sock.fileno())
        self._resume = self.loop.call_later(self.pause_s, self._listen_again)

    def _listen_again(self) -> None:
        self._resume = None
        if self.sock.fileno() >= 0:
            self.loop.add_reader(self.sock.fileno(), self._accept_ready)

    def close(self) -> None:
        if self._resume is not None:
            self._resume.cancel()
            self._resume = None
        if self.sock.fileno() >= 0:
            self.loop.remove_reader(self.sock.fileno())
            self.sock.close()
        for task in list(self._connecting):
            task.cancel()


async def listen(host: str, port: int) -> socket.socket:
    """A listening socket on HOST:PORT (an IPv4 or IPv6 address, or a name, resolved without
    blocking the loop)."""
    infos = await asyncio.get_running_loop().getaddrinfo(host, port, type=socket.SOCK_STREAM,
                                                         flags=socket.AI_PASSIVE)
    family, _, _, _, address = infos[0]
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # TIME_WAIT of a previous run
        sock.bind(address)
        sock.listen(128)
    except OSError:
        sock.close()
        raise
    return sock


def descriptors_needed(channels: Iterable, http_connections: int = 0) -> int:
    """FD_RESERVE, each tcp-server channel's connections and listener, and the HTTP API's
    (`http_connections` at most, and its listener: gcsd.api.http.service.HttpService.attach)."""
    http = http_connections + 1 if http_connections else 0
    return FD_RESERVE + http + sum(c.max_peers + 1 for c in channels if c.type == "tcp-server")


def ensure_descriptor_budget(needed: int) -> tuple[int, int]:
    """Raise the soft descriptor limit to `needed` if it is lower (never above the hard limit);
    returns (the soft limit now, needed)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft != resource.RLIM_INFINITY and soft < needed:
        target = needed if hard == resource.RLIM_INFINITY else min(hard, needed)
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
            soft = target
        except (ValueError, OSError):
            pass
    return soft, needed
