"""The `mqtt` channel: gcsd instances meet on an MQTT broker (SPEC.md "Fleet scale").

One MQTT message carries one MAVLink frame, byte-exact (signature included), QoS 0, never
retained. Topics under the channel's `topic` prefix T:

- role vehicle: every frame the channel sends is published to T/up/{src_sysid}/{src_compid}; the
  channel subscribes to T/down/all and to T/down/{S} for every system S it serves. The systems
  it serves are the sources of the frames it publishes: its own vehicles (their HEARTBEAT goes
  out as soon as the channel opens) and every system the router forwards up from the process's
  other channels (a flight controller behind a companion: its frames reach this channel through
  the learned routes). So the subscriptions follow the router exactly: a system whose frames
  the ground side can see is one the ground side can reach, and nothing else is received. The
  set only grows (at most 255 sysids) and is subscribed again after every reconnect.
- role ground: a frame targeted at system S (its target_system field, read from the raw
  header like the router does) is published to T/down/S; broadcasts (target 0, no target
  field, unknown message ids) to T/down/all. It subscribes to T/up/{S}/+ for each S of
  `sysids`, or to T/up/+/+ for `all`: several ground-side instances can split a fleet.

The broker is one peer of the channel while connected: the channel's counters count frames
and bytes as for any link, a payload that is not whole frames is a parse error, and frames
from every source go through the router. Dropped and counted:
- a payload over MAX_PAYLOAD_BYTES, unparsed (a parse error);
- role ground: a message on T/up/S/C any of whose frames (every frame the parser finds in it,
  after garbage or inside a frame with a bad CRC too) is not from system S: the whole message
  (`spoofed_dropped`), so that broker ACLs giving each vehicle only its own up/S topic cannot
  be bypassed;
- a retained message (either role; `retained_dropped`): the broker stored it earlier and hands
  it to every new subscriber, so a force-arm published once with the retain flag would be
  executed at every later start with no ground station anywhere. gcsd never publishes retained
  messages; a message published live with the flag reaches current subscribers with the flag
  clear (MQTT 3.1.1, 3.3.1.3) and is handled as any other. Frames are
published only while connected; a frame that finds the connection down, or more than
MAX_PENDING_FRAMES not yet written to the socket, is a counted drop, never an unbounded queue.

States: closed -> connecting (TCP, TLS and CONNECT in a worker thread, as they block) ->
waiting for CONNACK (CONNACK_TIMEOUT_S) and the SUBACK of the initial subscriptions ->
open (the channel's peer exists) -> closed when the socket is lost or the keepalive
(KEEPALIVE_S, pings from `loop_misc` each second) fails. transport.run_channel reopens it with
its capped backoff (0.5 s doubling to 5 s), so a broker that is down or restarting never
stops the daemon or its other channels. The password file is read at each connect, so a
rotated password takes effect at the next reconnect.

Why paho-mqtt used directly (with its external event loop hooks) rather than aiomqtt, which
wraps the same paho client: `Channel.write` is synchronous and must drop, not queue, when the
link is full. paho's `publish` is synchronous, queues one packet and reports the connection
state at once; aiomqtt's `publish` is a coroutine that waits for each message's completion
(a task per frame on a path that carries thousands of frames per second), and its receive path
adds a Message object and an asyncio.Queue hop per frame. paho-mqtt is the Eclipse Foundation's
reference client (MQTT 3.1.1 and 5, TLS, maintained since 2014, 2.x API); the adapter below is
the ~100 lines of socket hooks aiomqtt itself uses. MQTT 3.1.1 is spoken: every broker and
cloud IoT service accepts it, and nothing here needs a v5 feature.

Latency: the socket is TCP_NODELAY (paho leaves Nagle on, which with delayed ACKs holds small
frames for tens of milliseconds); brokers should do the same for their clients (Mosquitto:
`set_tcp_nodelay true`, as in sitl/fleet/mosquitto.conf).
"""

from __future__ import annotations

import asyncio
import secrets
import socket
import ssl
import weakref
from collections.abc import Callable, Iterable
from pathlib import Path

import paho.mqtt.client as paho
import structlog
from paho.mqtt.enums import CallbackAPIVersion, MQTTErrorCode

from gcsd.config.mqtt import MqttConfig
from gcsd.wire.codec import MAX_FRAME_BYTES, MESSAGE_INFO, STX_V2

log = structlog.get_logger("gcsd.links.mqtt")

KEEPALIVE_S = 15  # a silently dead broker is noticed within 1.5 x this; a killed one at once (RST/EOF)
CONNECT_TIMEOUT_S = 5.0  # TCP + TLS handshake
CONNACK_TIMEOUT_S = 10.0  # CONNACK and SUBACK
MAX_PENDING_FRAMES = 4096  # published but not yet written to the socket (about 1 MB): beyond, drop
DRAIN_BATCH = 256  # MQTT packets read per readiness event
MAX_PAYLOAD_BYTES = 4 * MAX_FRAME_BYTES  # one frame is at most 280 bytes; a bigger payload is dropped unparsed
MAX_SYSID = 255


# --- pure parts: frame headers, topics ----------------------------------------------------

def frame_source(raw: bytes) -> tuple[int, int]:
    if raw[0] == STX_V2:
        return raw[5], raw[6]
    return raw[3], raw[4]


def frame_target_system(raw: bytes) -> int:
    """The target_system of a frame read from its bytes (0: a broadcast, no target field, or an
    unknown message id); a MAVLink2 payload truncated before the field reads 0, as in the router."""
    if raw[0] == STX_V2:
        hlen, msgid = 10, raw[7] | (raw[8] << 8) | (raw[9] << 16)
    else:
        hlen, msgid = 6, raw[5]
    info = MESSAGE_INFO.get(msgid)
    if info is None or info.target_system_ofs < 0 or info.target_system_ofs >= raw[1]:
        return 0
    return raw[hlen + info.target_system_ofs]


def topic_source_sysid(topic: str) -> int | None:
    """Role ground: the S of TOPIC/up/S/C, which every frame of the message must come from (so a
    broker ACL that lets each vehicle publish only under its own up/S is not bypassed by a
    spoofed source sysid); None when the topic has no system number there (nothing can match it)."""
    part = topic.rsplit("/", 2)[-2]
    if not (part.isascii() and part.isdecimal()) or str(int(part)) != part or int(part) > MAX_SYSID:
        return None  # only the spelling gcsd publishes (up/7, not up/007): the one an ACL names
    return int(part)


class Topics:
    """Topic names under one prefix, built once each."""

    def __init__(self, prefix: str) -> None:
        self.prefix = prefix
        self.down_all = f"{prefix}/down/all"
        self._up: dict[tuple[int, int], str] = {}
        self._down = [f"{prefix}/down/{s}" for s in range(MAX_SYSID + 1)]
        self._down[0] = self.down_all

    def up(self, sysid: int, compid: int) -> str:
        topic = self._up.get((sysid, compid))
        if topic is None:
            topic = self._up[(sysid, compid)] = f"{self.prefix}/up/{sysid}/{compid}"
        return topic

    def down(self, target_system: int) -> str:
        return self._down[target_system]

    def ground_subscriptions(self, sysids: frozenset[int] | None) -> list[str]:
        if sysids is None:
            return [f"{self.prefix}/up/+/+"]
        return [f"{self.prefix}/up/{s}/+" for s in sorted(sysids)]

    def vehicle_subscriptions(self, served: Iterable[int]) -> list[str]:
        return [self.down_all] + [self._down[s] for s in sorted(served)]


# --- the asyncio adapter -----------------------------------------------------------------------

# role vehicle: the systems each channel serves, remembered across reconnects (a new connection
# subscribes to all of them at once instead of waiting for each system's next frame)
_SERVED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


class MqttLink:
    """One connection to the broker for one channel; `open()` returns (close, closed) like the
    other transports in transport.py."""

    def __init__(self, channel, cfg: MqttConfig) -> None:
        self.channel = channel
        self.cfg = cfg
        self.topics = Topics(cfg.topic)
        self.ground = cfg.role == "ground"
        self.served = _SERVED.setdefault(channel, set())  # role vehicle: the S of down/S, kept across reconnects
        self.loop = asyncio.get_running_loop()
        self.closed = self.loop.create_future()
        # frames handed to paho since its queue was last empty: an upper bound on those not yet
        # written. (Not counted with on_publish: paho builds a ReasonCode and a Properties object
        # per QoS 0 message for that callback, a quarter of the publishing cost.)
        self.pending = 0
        self._delivered = 0
        self._connack: asyncio.Future | None = None
        self._suback: dict[int, asyncio.Future] = {}
        self._fd = -1
        self._misc: asyncio.Task | None = None
        self.peer = None
        self.client_id = cfg.client_id or f"gcsd-{secrets.token_hex(6)}"
        self.client = paho.Client(CallbackAPIVersion.VERSION2, client_id=self.client_id, clean_session=True,
                                  protocol=paho.MQTTv311, reconnect_on_failure=False)
        self.client.connect_timeout = CONNECT_TIMEOUT_S
        self.client.suppress_exceptions = True  # paho contains a callback's exception (ours log their own)

    # --- connect ---------------------------------------------------------------------------
    async def open(self) -> tuple[Callable[[], None], asyncio.Future]:
        client, cfg = self.client, self.cfg
        if cfg.username is not None:
            password = None
            if cfg.password_file is not None:
                lines = Path(cfg.password_file).read_text().splitlines()  # OSError: retried with backoff
                password = lines[0] if lines else ""
            client.username_pw_set(cfg.username, password)
        if cfg.tls:
            context = ssl.create_default_context(cafile=cfg.ca_file)
            if cfg.cert_file:
                context.load_cert_chain(cfg.cert_file, cfg.key_file)
            client.tls_set_context(context)
        client.on_connect = self._on_connect
        client.on_subscribe = self._on_subscribe
        client.on_message = self._on_message
        client.on_disconnect = self._on_disconnect
        client.on_socket_close = self._on_socket_close
        self._connack = self.loop.create_future()
        try:
            await self.loop.run_in_executor(None, client.connect, cfg.host, cfg.port, KEEPALIVE_S)
            sock = client.socket()
            if sock is None:
                raise OSError("connection closed during connect")
            self._fd = sock.fileno()
            # one small frame per message: Nagle + delayed ACK would hold frames for up to 40 ms
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client.on_socket_register_write = self._register_write
            client.on_socket_unregister_write = self._unregister_write
            self.loop.add_reader(self._fd, self._read_ready)
            if client.want_write():
                self.loop.add_writer(self._fd, self._write_ready)
            self._misc = self.loop.create_task(self._keepalive())
            await asyncio.wait_for(self._connack, CONNACK_TIMEOUT_S)
            topics = (self.topics.ground_subscriptions(cfg.sysids) if self.ground
                      else self.topics.vehicle_subscriptions(self.served))
            await asyncio.wait_for(self._subscribe(topics), CONNACK_TIMEOUT_S)
            if self.closed.done():
                raise OSError("connection to the broker lost while subscribing")
        except BaseException:
            self.close()
            raise
        self.peer = self.channel.add_peer(("mqtt", cfg.broker), self._write)
        log.info("mqtt_connected", channel=self.channel.name, broker=cfg.broker, role=cfg.role,
                 topic=cfg.topic, client_id=self.client_id)
        return self.close, self.closed

    def _on_connect(self, client, userdata, flags, reason, properties) -> None:
        if self._connack is None or self._connack.done():
            return
        if reason.is_failure:
            self._connack.set_exception(OSError(f"broker refused the connection: {reason}"))
        else:
            self._connack.set_result(None)

    def _subscribe(self, topics: list[str]) -> asyncio.Future:
        rc, mid = self.client.subscribe([(t, 0) for t in topics])
        future = self.loop.create_future()
        if rc != MQTTErrorCode.MQTT_ERR_SUCCESS:
            future.set_exception(OSError(f"subscribe failed: {paho.error_string(rc)}"))
        else:
            self._suback[mid] = future
        return future

    def _on_subscribe(self, client, userdata, mid, reasons, properties) -> None:
        future = self._suback.pop(mid, None)
        refused = [r for r in reasons if r.is_failure]
        if refused:
            log.warning("mqtt_subscribe_refused", channel=self.channel.name, reason=str(refused[0]))
        if future is not None and not future.done():
            if refused:
                future.set_exception(OSError(f"broker refused a subscription: {refused[0]}"))
            else:
                future.set_result(None)

    # --- socket hooks (paho's external event loop interface) -------------------------------
    def _read_ready(self) -> None:
        client = self.client
        for _ in range(DRAIN_BATCH):
            before = self._delivered
            if client.loop_read() != MQTTErrorCode.MQTT_ERR_SUCCESS:
                return  # connection lost: paho closed the socket and called _on_disconnect
            sock = client.socket()
            if sock is None:
                return
            if self._delivered == before and not (hasattr(sock, "pending") and sock.pending()):
                return  # nothing more was waiting (or a packet is incomplete)

    def _write_ready(self) -> None:
        self.client.loop_write()

    def _register_write(self, client, userdata, sock) -> None:
        if self._fd >= 0:
            self.loop.add_writer(self._fd, self._write_ready)

    def _unregister_write(self, client, userdata, sock) -> None:
        self.pending = 0  # paho calls this when everything queued has been written
        if self._fd >= 0:
            self.loop.remove_writer(self._fd)

    async def _keepalive(self) -> None:
        while self.client.loop_misc() == MQTTErrorCode.MQTT_ERR_SUCCESS:
            await asyncio.sleep(1.0)

    def _on_socket_close(self, client, userdata, sock) -> None:
        if self._fd >= 0:
            self.loop.remove_reader(self._fd)
            self.loop.remove_writer(self._fd)
            self._fd = -1

    def _on_disconnect(self, client, userdata, flags, reason, properties) -> None:
        if not self.closed.done():
            self.closed.set_result(None)
        if self._connack is not None and not self._connack.done():
            self._connack.set_exception(OSError(f"disconnected: {reason}"))
        for future in self._suback.values():
            if not future.done():
                future.set_exception(OSError(f"disconnected: {reason}"))

    # --- frames ----------------------------------------------------------------------------
    def _on_message(self, client, userdata, message) -> None:
        self._delivered += 1
        channel = self.channel
        if message.retain:  # stored by the broker earlier (a stale command), not sent now: never acted on
            channel.stats.retained_dropped += 1
            return
        peer = self.peer
        if peer is None:
            return
        payload = message.payload
        if len(payload) > MAX_PAYLOAD_BYTES:
            peer.parser.stats.parse_errors += 1  # not what this link carries: dropped unparsed
            return
        source = None
        if self.ground:
            source = topic_source_sysid(message.topic)
            if source is None:
                channel.stats.spoofed_dropped += 1
                return
        now = channel.clock()
        channel.tick(now, channel.wall())
        # paho would swallow an exception silently (suppress_exceptions): the daemon's boundary counts it
        with channel.errors.guard("mqtt_receive", now, channel=channel.name, topic=message.topic):
            channel.receive(peer, payload, now, datagram=True, source_sysid=source)

    def _write(self, raw: bytes) -> bool:
        """The peer writer: one frame, one message, on the topic the frame's header selects."""
        if self.pending >= MAX_PENDING_FRAMES:
            return False
        if self.ground:
            topic = self.topics.down(frame_target_system(raw))
        else:
            sysid, compid = frame_source(raw)
            topic = self.topics.up(sysid, compid)
            if sysid not in self.served and sysid > 0:
                self._serve(sysid)
        info = self.client.publish(topic, raw, 0)
        if info.rc != MQTTErrorCode.MQTT_ERR_SUCCESS:
            return False
        self.pending += 1
        return True

    def _serve(self, sysid: int) -> None:
        """Role vehicle: a system now sends through this channel, so its down topic is taken."""
        self.served.add(sysid)
        self.client.subscribe(self.topics.down(sysid), 0)
        log.debug("mqtt_serving", channel=self.channel.name, sysid=sysid, topic=self.topics.down(sysid))

    # --- close -----------------------------------------------------------------------------
    def close(self) -> None:
        if self.peer is not None:
            self.channel.remove_peer(self.peer.key)
            self.peer = None
        if self._misc is not None:
            self._misc.cancel()
            self._misc = None
        client = self.client
        if self._fd >= 0:
            self.loop.remove_reader(self._fd)
            self.loop.remove_writer(self._fd)
            self._fd = -1
        client.on_socket_register_write = None
        client.on_socket_unregister_write = None
        client.on_disconnect = None
        if client.socket() is not None:
            client.disconnect()  # written at once (no write hook now); paho then closes the socket
            sock = client.socket()
            if sock is not None:  # the DISCONNECT could not be written (buffer full): just drop it
                sock.close()
        if not self.closed.done():
            self.closed.set_result(None)
        log.info("mqtt_closed", channel=self.channel.name, broker=self.cfg.broker)


async def open_channel(channel) -> tuple[Callable[[], None], asyncio.Future]:
    """transport._open's mqtt branch."""
    return await MqttLink(channel, channel.config.mqtt or MqttConfig()).open()
