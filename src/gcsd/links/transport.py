"""asyncio adapters: sockets and serial ports in, bytes to a Channel; one task per channel.

Each channel runs `run_channel(channel, send_pass, wakeup, opened, on_error)`: it opens the
transport (retrying with capped exponential backoff for clients and serial ports), then loops calling
`send_pass(channel, now)` (the Daemon's deferred scheduler pass), sleeping until the deadline it
returns or until `wakeup` is set (something was queued). Receiving happens in protocol
callbacks, which hand bytes to `Channel.receive`.

Errors are events, never crashes: a refused connection, a vanished serial device or a full
socket buffer is logged (an open failing again with the same error: at debug level) and counted
(`open_failures`); the channel reconnects, and the daemon keeps running.

- udp-server: one bound socket; an address that sends a good frame becomes a peer (see
  channel.py, "Admission"), answered until silent 30 s.
- udp-client: one connected socket; the remote is the peer from the start. With `broadcast`,
  SO_BROADCAST and the address is a broadcast address until a ground station answers with a
  good frame, then that station only (gcsd.links.discovery, ArduPilot's udp:ADDR:bcast).
- tcp-server: every accepted connection is a peer (served at once, or after its first good
  frame when the channel needs signatures; unauth.py bounds and times out the waiting ones).
  The accept loop is tcpserver.py: it pauses instead of spinning when the process is out of
  descriptors, and counts and rate-limits what it logs.
- tcp-client, serial: one peer while connected; reconnect after loss.

Host names are resolved (without blocking the loop) at every open, so a name whose address
changes, or that does not resolve yet, is picked up at the next attempt of the capped backoff.
A serial device that is missing or unplugged is opened again when its path (such as a
`/dev/serial/by-id/` link) is back, by the same backoff; with a list of bauds, a port that hears
no good frame is reopened at the next baud (baudhunt.py).

A server channel (udp-server, tcp-server) that cannot open its address the first time is a
startup failure (`ChannelStartError`, exit 1), never a daemon that sits there half-working;
after it has been open once, it is reopened with backoff like the others.
"""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Callable

import structlog

from gcsd.config.schema import SERVER_TYPES
from gcsd.links.baudhunt import BaudHunt
from gcsd.links.channel import Channel
from gcsd.links.discovery import BroadcastLock
from gcsd.links.tcpserver import Listener, listen
from gcsd.wire import speedups

log = structlog.get_logger("gcsd.links.transport")

BACKOFF_START_S = 0.5
BACKOFF_MAX_S = 5.0
WRITE_BUFFER_LIMIT = 64 * 1024
UDP_RCVBUF = 4 * 1024 * 1024


class ChannelStartError(Exception):
    """A server channel could not open its address at start."""


class _Datagram:
    """A non-blocking UDP socket read straight from the selector.

    asyncio's datagram transport reads one datagram per loop iteration; under load that costs a
    full loop pass per packet. Here each readiness event drains up to DRAIN_BATCH datagrams (one
    recvmmsg(2) when gcsd.wire._speedups is built: speedups.py). What the peers' writers write during
    a pass of the loop is sent at its end, together (`flush`: one sendmmsg(2) when compiled), in
    the order written: a routed batch goes out as one system call, not one per frame. A datagram
    the kernel refuses then (a full socket buffer) is a counted drop, never a queue; `packets_out`
    counts what was handed to the socket.
    """

    DRAIN_BATCH = 64

    def __init__(self, channel: Channel, sock: socket.socket, accept_new_peers: bool,
                 bcast: BroadcastLock | None = None) -> None:
        self.channel = channel
        self.sock = sock
        self.accept_new_peers = accept_new_peers
        self.bcast = bcast
        self.loop = asyncio.get_running_loop()
        self.closed = self.loop.create_future()
        self._recv_batch = speedups.receiver(sock)  # recvmmsg(2) when compiled (speedups.py)
        self._send_batch = speedups.sender(sock)  # sendmmsg(2) when compiled
        self._pending: list[tuple[bytes, tuple]] = []
        self.loop.add_reader(sock.fileno(), self._read_ready)
        channel.make_writer = self.writer

    def writer(self, addr) -> Callable[[bytes], bool]:
        pending = self._pending
        call_soon, flush = self.loop.call_soon, self.flush

        def write(data: bytes) -> bool:
            if not pending:
                call_soon(flush)  # at the end of this pass of the loop
            pending.append((data, addr))
            return True

        return write

    def flush(self) -> None:
        pending = self._pending
        if not pending or self.sock.fileno() < 0:
            pending.clear()
            return
        items = pending.copy()
        pending.clear()
        try:
            sent = self._send_batch(self.sock, items)
        except (OSError, TypeError, ValueError, OverflowError) as exc:  # an address sendto would refuse too
            log.warning("udp_send_failed", channel=self.channel.name, datagrams=len(items), error=str(exc))
            sent = 0
        if sent < len(items):
            self.channel.stats.drops += len(items) - sent

    def _read_ready(self) -> None:
        channel = self.channel
        try:
            batch = self._recv_batch(self.sock, self.DRAIN_BATCH)
        except OSError as exc:  # ICMP port unreachable from an earlier send, and the like
            log.debug("udp_error_received", channel=channel.name, error=str(exc))
            return  # what waits behind it is read on the next readiness event, at once
        if not batch:
            return
        peers = channel.peers
        now = channel.clock()
        channel.tick(now, channel.wall())  # the time of this wake-up, for everything it does
        for data, addr in batch:
            peer = peers.get(addr)
            if peer is None:
                if self.bcast is not None:
                    self._from_lan(addr, data, now)
                    continue
                if not self.accept_new_peers:
                    continue
                peer = channel.stranger(addr, now)
            channel.receive(peer, data, now, datagram=True)

    # --- broadcast discovery (gcsd.links.discovery): one peer, keyed by the broadcast address ---------
    def broadcast_writer(self) -> Callable[[bytes], bool]:
        sendto, bcast, clock, name = self.sock.sendto, self.bcast, self.channel.clock, self.channel.name

        def write(data: bytes) -> bool:
            dest, released = bcast.destination(clock())
            if released:
                log.info("broadcast_resumed", channel=name, silent_s=bcast.silent_s)
            try:
                sendto(data, dest)
            except OSError:
                return False
            return True

        return write

    def _from_lan(self, addr, data: bytes, now: float) -> None:
        """A datagram on a broadcast channel: read if it is from the station (or none yet); its
        first good frame locks the channel onto its sender."""
        bcast = self.bcast
        peer = self.channel.peers.get(bcast.address)
        if peer is None or not bcast.accepts(addr):
            return
        self.channel.receive(peer, data, now, datagram=True)
        if peer.last_rx_s == now and bcast.heard(addr, now):  # a frame was accepted
            log.info("broadcast_answered", channel=self.channel.name, station=f"{addr[0]}:{addr[1]}")

    def close(self) -> None:
        if self.sock.fileno() >= 0:
            self.flush()
            self.loop.remove_reader(self.sock.fileno())
            self.sock.close()
        if not self.closed.done():
            self.closed.set_result(None)


class _Stream(asyncio.Protocol):
    """A TCP connection or a serial port: one peer."""

    def __init__(self, channel: Channel, key: object | None = None, server: bool = False) -> None:
        self.channel = channel
        self.key = key
        self.server = server
        self.peer = None
        self.closed = asyncio.get_running_loop().create_future()

    def connection_made(self, transport) -> None:
        self.transport = transport
        if self.key is None:
            addr = transport.get_extra_info("peername")
            self.key = addr if addr else id(self)
        if self.server:
            self.peer = self.channel.connect_peer(self.key, self._write, transport.close)
        else:
            self.peer = self.channel.add_peer(self.key, self._write)
        log.info("peer_connected", channel=self.channel.name, peer=str(self.key))

    def _write(self, data: bytes) -> bool:
        transport = self.transport
        if transport.is_closing() or transport.get_write_buffer_size() > WRITE_BUFFER_LIMIT:
            return False
        transport.write(data)
        return True

    def data_received(self, data: bytes) -> None:
        channel = self.channel
        now = channel.clock()
        channel.tick(now, channel.wall())
        channel.receive(self.peer, data, now)

    def connection_lost(self, exc) -> None:
        self.channel.remove_peer(self.key)
        log.info("peer_left", channel=self.channel.name, peer=str(self.key), error=str(exc) if exc else None)
        if not self.closed.done():
            self.closed.set_result(exc)


async def resolve(host: str, port: int, kind: int = socket.SOCK_DGRAM) -> tuple[str, int]:
    """HOST (a name or an IPv4 address) -> its first IPv4 address, without blocking the loop."""
    infos = await asyncio.get_running_loop().getaddrinfo(host, port, family=socket.AF_INET, type=kind)
    return infos[0][4][:2]


async def _open(channel: Channel, baud: int | None = None):
    """Open the transport; returns (closer, closed_future)."""
    loop = asyncio.get_running_loop()
    cfg = channel.config
    kind = cfg.type
    if kind in ("udp-server", "udp-client"):
        host, port = await resolve(*cfg.address)
        server = kind == "udp-server"
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, UDP_RCVBUF)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, UDP_RCVBUF)
        if server:
            # no SO_REUSEADDR: on Linux it lets a second UDP socket bind the same port and take
            # its datagrams (another gcsd, or QGroundControl's own 14550), and a taken port must
            # be a startup failure instead (UDP has no TIME_WAIT to work around)
            sock.bind((host, port))
        else:
            sock.bind(("127.0.0.1" if host.startswith("127.") else "0.0.0.0", 0))
            if cfg.broadcast:
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        sock.setblocking(False)
        addr = None if server else (host, port)
        bcast = BroadcastLock(addr) if not server and cfg.broadcast else None
        proto = _Datagram(channel, sock, accept_new_peers=server, bcast=bcast)
        channel.local_address = sock.getsockname()[:2]
        if not server:
            channel.add_peer(addr, proto.broadcast_writer() if bcast else proto.writer(addr))
            log.info("peer_joined", channel=channel.name, peer=f"{addr[0]}:{addr[1]}")
        return proto.close, proto.closed
    if kind == "local":  # the HTTP API's channel (gcsd.api.http.local): open = the API listening
        return await channel.open()
    if kind == "tcp-server":
        host, port = cfg.address
        server = Listener(channel, await listen(host, port), lambda: _Stream(channel, server=True))
        channel.local_address = server.sock.getsockname()[:2]
        closed = loop.create_future()

        def close():
            server.close()
            for key in list(channel.peers) + list(channel._waiting):
                channel.remove_peer(key)
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
            loop, lambda: _Stream(channel, key=cfg.device), cfg.device, baudrate=baud or cfg.baud
        )
        return transport.close, proto.closed
    if kind == "websocket":  # clients come through the HTTP API's /v1/ws/raw and the channel's own listener
        from gcsd.links import websocket

        return await websocket.open_channel(channel)
    if kind == "mqtt":
        from gcsd.links import mqtt  # paho-mqtt is imported only by daemons that use a broker

        return await mqtt.open_channel(channel)
    raise ValueError(f"unknown channel type {kind!r}")


def _describe(channel: Channel) -> str:
    if channel.local_address:
        return f"{channel.local_address[0]}:{channel.local_address[1]}"
    return channel.config.device or (channel.config.mqtt.broker if channel.config.mqtt else "")


PASS_FAILED_PAUSE_S = 0.1
CLOSE_WAIT_S = 1.0


async def run_channel(
    channel: Channel,
    send_pass: Callable[[Channel, float], float | None],
    wakeup: asyncio.Event,
    opened: Callable[[Channel, bool], None] = lambda channel, ok: None,
    on_error: Callable[[str, float], None] | None = None,
) -> None:
    """Open, serve and reopen one channel until cancelled.

    `opened(channel, True)` after each successful open; `opened(channel, False)` after the
    first failed attempt of a client channel (a flight controller or broker that is down at
    boot), so that the daemon is ready once every channel has been tried, not when every peer
    happens to be up.

    `send_pass` guards its own parts; should it raise all the same, `on_error(component, now)`
    counts it and the loop goes on after a short pause (never a hot loop, never a dead channel).
    """
    backoff = BACKOFF_START_S
    clock = channel.clock
    ever_opened = False
    last_error: str | None = None  # of the last failed open, while it keeps failing
    hunt = BaudHunt(channel.config.bauds) if channel.config.type == "serial" else None
    while True:
        baud = hunt.opening(clock()) if hunt is not None else None
        try:
            close, closed = await _open(channel, baud)
        except Exception as exc:  # noqa: BLE001  (OSError, serial.SerialException and friends: retried)
            error = str(exc) if isinstance(exc, OSError) else repr(exc)
            if not ever_opened and channel.config.type in SERVER_TYPES:
                host, port = channel.config.address
                raise ChannelStartError(
                    f"channel {channel.name}: cannot open {channel.config.type} {host}:{port}: {error}") from None
            # once per distinct error: a peer down for hours, or a port another process holds,
            # is one warning (then debug), not one every BACKOFF_MAX_S; open_failures counts all
            (log.debug if error == last_error else log.warning)(
                "channel_open_failed", channel=channel.name, error=error, retry_s=backoff)
            last_error = error
            channel.stats.open_failures += 1
            opened(channel, False)
            await asyncio.sleep(backoff)
            backoff = min(backoff * 2, BACKOFF_MAX_S)
            continue
        ever_opened = True
        backoff = BACKOFF_START_S
        last_error = None
        log.info("channel_opened", channel=channel.name, type=channel.config.type, address=_describe(channel),
                 baud=baud)
        opened(channel, True)
        next_baud = False
        try:
            while not closed.done():
                now = clock()
                channel.tick(now, channel.wall())  # the send pass's time
                if hunt is not None and _probe_over(channel, hunt, now):
                    next_baud = True
                    break
                try:
                    deadline = send_pass(channel, now)
                except Exception:
                    if on_error is None:
                        raise
                    on_error(f"channel:{channel.name}", now)
                    deadline = now + PASS_FAILED_PAUSE_S
                timeout = 0.5 if deadline is None else max(0.0, min(deadline - clock(), 0.5))
                if timeout > 0:
                    wakeup.clear()
                    waiter = asyncio.ensure_future(wakeup.wait())
                    done, _ = await asyncio.wait(
                        {waiter, closed}, timeout=timeout, return_when=asyncio.FIRST_COMPLETED)
                    if waiter not in done:
                        waiter.cancel()
                else:
                    await asyncio.sleep(0)
        finally:
            close()
        # the old connection's connection_lost must run before a new one takes the same peer key
        await asyncio.wait({closed}, timeout=CLOSE_WAIT_S)
        if next_baud:  # a baud that heard nothing: the next one at once
            log.info("serial_baud_changed", channel=channel.name, baud=hunt.bauds[hunt.index])
            continue
        if hunt is not None:
            hunt.closed()
        log.warning("channel_closed", channel=channel.name, retry_s=backoff)
        await asyncio.sleep(backoff)


def _probe_over(channel: Channel, hunt: BaudHunt, now: float) -> bool:
    """A serial port probing a baud list: lock on the first good frame, or move on (baudhunt.py)."""
    if hunt.locked:
        return False
    peer = channel.peers.get(channel.config.device)
    if peer is not None and peer.heard:
        hunt.heard()
        log.info("serial_baud_locked", channel=channel.name, baud=hunt.bauds[hunt.index])
        return False
    return hunt.expired(now)
