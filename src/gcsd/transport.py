"""asyncio adapters: sockets and serial ports in, bytes to a Channel; one task per channel.

Each channel runs `run_channel(channel, send_pass, stopping)`: it opens the transport (retrying
with capped exponential backoff for clients and serial ports), then loops calling
`send_pass(channel, now)` (the GCS's deferred scheduler pass), sleeping until the deadline it
returns or until woken (`wake(channel)`, for pushed messages). Receiving happens in protocol
callbacks, which hand bytes to `Channel.receive`.

Errors are events, never crashes: a refused connection, a vanished serial device or a full
socket buffer is logged and counted; the channel reconnects, and the daemon keeps running.

- udp-server: one bound socket; every address that sends is a peer, answered until silent 30 s.
- udp-client: one connected socket; the remote is the peer from the start.
- tcp-server: every accepted connection is a peer.
- tcp-client, serial: one peer while connected; reconnect after loss.
"""

from __future__ import annotations

import asyncio
import socket
from typing import Callable

import structlog

from .channel import Channel

log = structlog.get_logger("gcsd.transport")

BACKOFF_START_S = 0.5
BACKOFF_MAX_S = 5.0
WRITE_BUFFER_LIMIT = 64 * 1024
UDP_RCVBUF = 4 * 1024 * 1024


class _Datagram(asyncio.DatagramProtocol):
    def __init__(self, channel: Channel, accept_new_peers: bool) -> None:
        self.channel = channel
        self.accept_new_peers = accept_new_peers
        self.transport: asyncio.DatagramTransport | None = None
        self.closed = asyncio.get_running_loop().create_future()

    def connection_made(self, transport) -> None:
        self.transport = transport

    def writer(self, addr) -> Callable[[bytes], bool]:
        def write(data: bytes) -> bool:
            transport = self.transport
            if transport is None or transport.is_closing():
                return False
            if transport.get_write_buffer_size() > WRITE_BUFFER_LIMIT:
                return False
            try:
                transport.sendto(data, addr)
            except OSError:
                return False
            return True

        return write

    def datagram_received(self, data: bytes, addr) -> None:
        channel = self.channel
        peer = channel.peers.get(addr)
        if peer is None:
            if not self.accept_new_peers:
                return
            peer = channel.add_peer(addr, self.writer(addr))
            log.info("peer_joined", channel=channel.name, peer=f"{addr[0]}:{addr[1]}")
        channel.receive(peer, data, datagram=True)

    def error_received(self, exc: Exception) -> None:
        # ICMP port unreachable and the like: the peer is not there (yet); nothing to do
        log.debug("udp_error_received", channel=self.channel.name, error=str(exc))

    def connection_lost(self, exc) -> None:
        if not self.closed.done():
            self.closed.set_result(exc)


class _Stream(asyncio.Protocol):
    """A TCP connection or a serial port: one peer."""

    def __init__(self, channel: Channel, key: object | None = None) -> None:
        self.channel = channel
        self.key = key
        self.peer = None
        self.closed = asyncio.get_running_loop().create_future()

    def connection_made(self, transport) -> None:
        self.transport = transport
        if self.key is None:
            addr = transport.get_extra_info("peername")
            self.key = addr if addr else id(self)
        self.peer = self.channel.add_peer(self.key, self._write)
        log.info("peer_joined", channel=self.channel.name, peer=str(self.key))

    def _write(self, data: bytes) -> bool:
        transport = self.transport
        if transport.is_closing() or transport.get_write_buffer_size() > WRITE_BUFFER_LIMIT:
            return False
        transport.write(data)
        return True

    def data_received(self, data: bytes) -> None:
        self.channel.receive(self.peer, data)

    def connection_lost(self, exc) -> None:
        self.channel.remove_peer(self.key)
        log.info("peer_left", channel=self.channel.name, peer=str(self.key), error=str(exc) if exc else None)
        if not self.closed.done():
            self.closed.set_result(exc)


async def _open(channel: Channel):
    """Open the transport; returns (closer, closed_future)."""
    loop = asyncio.get_running_loop()
    cfg = channel.config
    kind = cfg.type
    if kind in ("udp-server", "udp-client"):
        host, port = cfg.address
        server = kind == "udp-server"
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_RCVBUF)
        if server:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((host, port))
        else:
            sock.bind(("0.0.0.0" if host != "127.0.0.1" else "127.0.0.1", 0))
        sock.setblocking(False)
        transport, proto = await loop.create_datagram_endpoint(
            lambda: _Datagram(channel, accept_new_peers=server), sock=sock
        )
        if not server:
            addr = (socket.gethostbyname(host), port)
            channel.add_peer(addr, proto.writer(addr))
        channel.local_address = transport.get_extra_info("sockname")[:2]
        return transport.close, proto.closed
    if kind == "tcp-server":
        host, port = cfg.address
        server = await loop.create_server(lambda: _Stream(channel), host, port, reuse_address=True)
        channel.local_address = server.sockets[0].getsockname()[:2]
        closed = loop.create_future()

        def close():
            server.close()
            for peer in list(channel.peers):
                channel.remove_peer(peer)
            if not closed.done():
                closed.set_result(None)

        return close, closed
    if kind == "tcp-client":
        host, port = cfg.address
        transport, proto = await loop.create_connection(lambda: _Stream(channel), host, port)
        transport.get_extra_info("socket").setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        channel.local_address = transport.get_extra_info("sockname")[:2]
        return transport.close, proto.closed
    if kind == "serial":
        import serial_asyncio

        transport, proto = await serial_asyncio.create_serial_connection(
            loop, lambda: _Stream(channel, key=cfg.device), cfg.device, baudrate=cfg.baud
        )
        return transport.close, proto.closed
    raise ValueError(f"unknown channel type {kind!r}")


def _describe(channel: Channel) -> str:
    if channel.local_address:
        return f"{channel.local_address[0]}:{channel.local_address[1]}"
    return channel.config.device or ""


async def run_channel(
    channel: Channel,
    send_pass: Callable[[Channel, float], float | None],
    wakeup: asyncio.Event,
    opened: Callable[[Channel], None] = lambda channel: None,
) -> None:
    """Open, serve and reopen one channel until cancelled."""
    backoff = BACKOFF_START_S
    clock = channel.clock
    while True:
        try:
            close, closed = await _open(channel)
        except (OSError, ValueError, ImportError) as exc:
            log.warning("channel_open_failed", channel=channel.name, error=str(exc), retry_s=backoff)
            await asyncio.sleep(backoff)
            backoff = min(backoff * 2, BACKOFF_MAX_S)
            continue
        except Exception as exc:  # serial.SerialException and friends
            log.warning("channel_open_failed", channel=channel.name, error=repr(exc), retry_s=backoff)
            await asyncio.sleep(backoff)
            backoff = min(backoff * 2, BACKOFF_MAX_S)
            continue
        backoff = BACKOFF_START_S
        log.info("channel_opened", channel=channel.name, type=channel.config.type, address=_describe(channel))
        opened(channel)
        try:
            while not closed.done():
                now = clock()
                deadline = send_pass(channel, now)
                timeout = 0.5 if deadline is None else max(0.0, min(deadline - clock(), 0.5))
                if timeout > 0:
                    wakeup.clear()
                    waiter = asyncio.ensure_future(wakeup.wait())
                    done, _ = await asyncio.wait({waiter, closed}, timeout=timeout)
                    if waiter not in done:
                        waiter.cancel()
                else:
                    await asyncio.sleep(0)
        finally:
            close()
        log.warning("channel_closed", channel=channel.name, retry_s=backoff)
        await asyncio.sleep(backoff)
