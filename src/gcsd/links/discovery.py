"""Broadcast discovery for a udp-client channel with `broadcast: true`. Pure: `now` is passed in.

QGroundControl listens on UDP 14550 (bound to every address) and waits for a vehicle to speak
first; on a LAN it cannot know the vehicle's address. ArduPilot boards solve this with a
broadcast output (`udp:ADDR:bcast`, libraries/AP_HAL_Linux/UDPDevice.cpp and AP_HAL_SITL's
UDPDevice): they send to the broadcast address with SO_BROADCAST and `connect()` the socket to
the source of the first packet received, which from then on is the only peer.

gcsd does the same, with two differences a LAN user would expect:
- it locks onto the first source of a *good* frame (valid CRC, signed where signing is
  required), not of any datagram, so a stray packet on the LAN cannot capture the vehicle;
- when the locked ground station has been silent for STATION_SILENT_S (30 s, the udp-server's
  peer timeout), it goes back to broadcasting, so a ground station restarted on another host finds
  the vehicle again (ArduPilot stays connected to the old address until it reboots).

States:  BROADCASTING --good frame from A--> LOCKED(A) --A silent 30 s--> BROADCASTING
While LOCKED(A), datagrams from other sources are dropped, as a connected socket drops them.

Which broadcast address: 255.255.255.255 (the limited broadcast) reaches every host on the
LAN of the default route's interface, and also sockets on this host bound to 0.0.0.0. A
subnet's directed broadcast (e.g. 192.168.1.255) picks the interface. On loopback, 127.255.255.255
reaches sockets bound to 0.0.0.0 but NOT sockets bound to 127.0.0.1 (measured on Linux 6:
broadcasts are delivered only to sockets bound to the wildcard or the broadcast address), which
is fine for QGroundControl: it binds the wildcard address.
"""

from __future__ import annotations

STATION_SILENT_S = 30.0

Address = tuple[str, int]


class BroadcastLock:
    """Where a broadcast channel sends, and whose datagrams it takes."""

    __slots__ = ("address", "last_heard_s", "silent_s", "station")

    def __init__(self, address: Address, silent_s: float = STATION_SILENT_S) -> None:
        self.address = address  # the broadcast address and port
        self.silent_s = silent_s
        self.station: Address | None = None  # the ground station locked onto
        self.last_heard_s = 0.0

    def accepts(self, source: Address) -> bool:
        """Whether a datagram from `source` is read at all."""
        return self.station is None or source == self.station

    def heard(self, source: Address, now: float) -> bool:
        """`source` sent a good frame; returns True when this locks the channel onto it."""
        self.last_heard_s = now
        if self.station is None:
            self.station = source
            return True
        return False

    def destination(self, now: float) -> tuple[Address, bool]:
        """Where to send now, and whether the lock was just released (the station fell silent)."""
        if self.station is not None and now - self.last_heard_s > self.silent_s:
            self.station = None
            return self.address, True
        return (self.station or self.address), False
