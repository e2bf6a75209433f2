"""Unauthenticated tcp-server connections (unauth.py, channel.py): bounded by max_peers with one
waiting slot always left, the host holding the most pushed out first, timed out after
UNAUTHENTICATED_TIMEOUT_S, never at the expense of a served station. Float clock, in-memory
writers; `serve_on_connect` False is what a channel that requires signatures gets (gcs.py)."""

from __future__ import annotations

from test_channel_admission import heartbeat, make_channel

from gcsd.links.unauth import UNAUTHENTICATED_TIMEOUT_S, evictee, expired, waiting_slots


class Conn:
    def __init__(self, ch, host: str, port: int) -> None:
        self.key = (host, port)
        self.closed = False
        self.peer = ch.connect_peer(self.key, lambda data: True, self.close)

    def close(self) -> None:
        self.closed = True


def signed_channel(max_peers: int = 3):
    ch, _outbox, _handled = make_channel(type="tcp-server", max_peers=max_peers)
    ch.serve_on_connect = False
    clock = [0.0]
    ch.clock = lambda: clock[0]
    return ch, clock


def test_a_flood_of_idle_connections_holds_at_most_max_peers_and_closes_the_rest():
    ch, clock = signed_channel(max_peers=3)
    conns = []
    for i in range(1100):
        clock[0] = i * 0.001
        conns.append(Conn(ch, "10.0.0.66", 1000 + i))
    open_ = [c for c in conns if not c.closed]
    assert len(open_) == 3 and [c.key[1] for c in open_] == [2097, 2098, 2099], "the newest three"
    assert ch.stats.unauthenticated_closed == 1097
    assert ch.snapshot()["unauthenticated_closed"] == 1097


def test_a_station_that_authenticates_is_served_and_idle_ones_never_push_it_out():
    ch, _clock = signed_channel(max_peers=3)
    station = Conn(ch, "192.168.1.5", 40000)
    ch.receive(station.peer, heartbeat(), 0.5)  # a good frame (the channel's verify accepts it here)
    assert station.key in ch.peers
    flood = [Conn(ch, "10.0.0.66", 1000 + i) for i in range(50)]
    assert not station.closed and station.key in ch.peers
    assert sum(not c.closed for c in flood) == 2, "served + waiting = max_peers"


def test_a_station_connecting_during_a_flood_from_another_host_keeps_its_slot():
    ch, clock = signed_channel(max_peers=3)
    for i in range(10):
        Conn(ch, "10.0.0.66", 1000 + i)
    station = Conn(ch, "192.168.1.5", 40000)
    for i in range(10, 200):  # the flood goes on while the station has not spoken yet
        clock[0] = i * 0.001
        Conn(ch, "10.0.0.66", 1000 + i)
    assert not station.closed
    ch.receive(station.peer, heartbeat(), 0.3)
    assert station.key in ch.peers, "it authenticated in time and is served"


def test_when_every_slot_is_served_one_waiting_slot_remains_for_a_newcomer():
    ch, clock = signed_channel(max_peers=2)
    served = [Conn(ch, f"192.168.1.{i}", 40000) for i in (1, 2)]
    for i, c in enumerate(served):
        ch.receive(c.peer, heartbeat(sysid=200 + i), 0.1 * (i + 1))
    newcomer = Conn(ch, "192.168.1.3", 40000)
    assert not newcomer.closed and ch.stats.unauthenticated_closed == 0
    clock[0] = 5.0
    ch.receive(newcomer.peer, heartbeat(sysid=210), 5.0)
    assert newcomer.key in ch.peers and served[0].closed, "it replaced the served peer silent the longest"
    assert ch.stats.peers_replaced == 1 and ch.stats.unauthenticated_closed == 0


def test_a_connection_still_unauthenticated_after_the_timeout_is_closed_and_a_talking_one_is_not():
    ch, _clock = signed_channel(max_peers=4)
    idle = Conn(ch, "10.0.0.66", 1000)
    garbage = Conn(ch, "10.0.0.67", 1001)
    station = Conn(ch, "192.168.1.5", 40000)
    ch.receive(station.peer, heartbeat(), 2.0)
    ch.receive(garbage.peer, b"\x00not mavlink" * 10, 3.0)  # activity, but not a good frame
    assert ch.sweep(UNAUTHENTICATED_TIMEOUT_S - 0.01) == [] and not idle.closed and not garbage.closed
    ch.sweep(UNAUTHENTICATED_TIMEOUT_S + 1.0)  # the sweep runs once a second
    assert idle.closed and garbage.closed and not station.closed
    assert ch.stats.unauthenticated_closed == 2 and list(ch.peers) == [station.key]


def test_where_no_signature_is_needed_a_silent_connection_is_served_and_not_timed_out():
    ch, _outbox, _handled = make_channel(type="tcp-server", max_peers=2)
    listener = Conn(ch, "192.168.1.5", 40000)  # a telemetry logger that never sends
    ch.sweep(1000.0)
    assert not listener.closed and listener.key in ch.peers
    Conn(ch, "10.0.0.66", 1)
    Conn(ch, "10.0.0.66", 2)  # full: the unheard connection served the longest goes first
    assert listener.closed and ch.stats.unauthenticated_closed == 1 and ch.stats.peers_replaced == 1


def test_the_pure_rules():
    class W:
        def __init__(self, key, t):
            self.key, self.last_rx_s = key, t

    waiting = {w.key: w for w in (W(("a", 1), 5.0), W(("b", 1), 1.0), W(("b", 2), 2.0), W(("a", 2), 0.5),
                                  W(("a", 3), 3.0))}
    assert evictee(waiting) == ("a", 2), "the oldest of the host holding the most"
    assert evictee({}) is None
    assert expired(waiting, 10.5) == [("a", 2)] and expired(waiting, 10.49) == []
    assert waiting_slots(8, 0) == 8 and waiting_slots(8, 8) == 1 and waiting_slots(8, 20) == 1


# --- the accept loop when the process is out of descriptors (tcpserver.py) ----------------------

def test_accept_out_of_descriptors_pauses_counts_and_logs_once_then_accepts_again():
    import asyncio
    import errno
    import socket

    from structlog.testing import capture_logs

    from gcsd.links.tcpserver import Listener, listen

    class OutOfDescriptors:
        """The real listening socket, whose accept() fails with EMFILE while `failing`."""

        def __init__(self, sock) -> None:
            self.sock, self.failing, self.attempts = sock, True, 0

        def accept(self):
            self.attempts += 1
            if self.failing:
                raise OSError(errno.EMFILE, "Too many open files")
            return self.sock.accept()

        def __getattr__(self, name):
            return getattr(self.sock, name)

    ch, _clock = signed_channel()
    accepted = []

    class Proto(asyncio.Protocol):
        def connection_made(self, transport):
            accepted.append(transport)

    async def main():
        sock = OutOfDescriptors(await listen("127.0.0.1", 0))
        listener = Listener(ch, sock, Proto, pause_s=0.05)
        client = socket.create_connection(sock.getsockname())
        await asyncio.sleep(0.5)  # the listening socket stays readable all along
        attempts = sock.attempts
        sock.failing = False
        for _ in range(100):
            if accepted:
                break
            await asyncio.sleep(0.01)
        client.close()
        for t in accepted:
            t.close()
        listener.close()
        return attempts

    with capture_logs() as logs:
        attempts = asyncio.run(main())
    assert 3 <= attempts <= 12, f"one attempt per pause, not a hot loop: {attempts}"
    assert ch.stats.accept_failures == attempts
    assert [e["event"] for e in logs].count("accept_failed") == 1, "logged once per interval (the clock stood still)"
    assert len(accepted) == 1, "accepted once descriptors were free again (the positive control)"


def test_a_tcp_server_listens_on_ipv4_ipv6_and_names():
    import asyncio
    import socket

    from gcsd.links.tcpserver import listen

    hosts = {"127.0.0.1": socket.AF_INET, "localhost": socket.AF_INET}
    try:  # only where the machine has IPv6 loopback (some containers do not)
        with socket.socket(socket.AF_INET6) as probe:
            probe.bind(("::1", 0))
        hosts["::1"] = socket.AF_INET6
    except OSError:
        pass

    async def families() -> dict[str, int]:
        out = {}
        for host in hosts:
            sock = await listen(host, 0)
            out[host] = sock.family
            sock.close()
        return out

    assert asyncio.run(families()) == hosts


def test_where_no_signature_is_needed_a_flood_from_one_host_pushes_out_only_its_own():
    ch, _outbox, _handled = make_channel(type="tcp-server", max_peers=3)
    station = Conn(ch, "192.168.1.5", 40000)  # connected, has not spoken yet
    for i in range(100):
        Conn(ch, "10.0.0.66", 1000 + i)
    assert not station.closed and station.key in ch.peers
    ch.receive(station.peer, heartbeat(), 1.0)
    assert ch.stats.unauthenticated_closed == 98


def test_the_descriptor_budget_counts_every_tcp_connection_a_channel_can_hold_and_raises_the_soft_limit():
    import resource

    from gcsd.config import parse_config
    from gcsd.links.tcpserver import FD_RESERVE, descriptors_needed, ensure_descriptor_budget

    config = parse_config("channels:\n"
                          "  - {name: a, type: tcp-server, address: '127.0.0.1:0', max_peers: 64}\n"
                          "  - {name: b, type: tcp-server, address: '127.0.0.1:0'}\n"
                          "  - {name: c, type: udp-server, address: '127.0.0.1:0', max_peers: 64}\n", "t.yaml")
    assert descriptors_needed(config.channels) == FD_RESERVE + 65 + 9, "udp peers hold no descriptor"
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    try:
        resource.setrlimit(resource.RLIMIT_NOFILE, (256, hard))
        assert ensure_descriptor_budget(300) == (min(300, hard), 300)
        assert resource.getrlimit(resource.RLIMIT_NOFILE)[0] == min(300, hard)
        assert ensure_descriptor_budget(100) == (min(300, hard), 100), "never lowered"
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
