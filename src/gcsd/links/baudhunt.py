"""Which baud a serial channel opens at next: a list of bauds (SPEC.md "Companion routing",
`baud: [921600, 115200, 57600]`) tried in turn until a good frame arrives. Pure: `now` passed in.

States: probing (at bauds[index], opened at `opened_s`) -> locked (a good frame arrived at the
current baud). While probing, a port that has heard no good frame PROBE_S after it opened is
closed by the transport and opened again at the next baud of the list, round and round
(`expired`). Once locked, the baud stays: a device that is unplugged and comes back is opened at
the baud that worked, and probing starts again from there only if that baud hears nothing.
A single baud never expires: there is nothing else to try.
"""

from __future__ import annotations

PROBE_S = 2.0  # a flight controller sends HEARTBEAT at 1 Hz: two chances per baud


class BaudHunt:
    __slots__ = ("bauds", "index", "locked", "opened_s")

    def __init__(self, bauds: tuple[int, ...]) -> None:
        self.bauds = bauds
        self.index = 0
        self.locked = False
        self.opened_s: float | None = None

    def opening(self, now: float) -> int:
        """The baud to open at now."""
        self.opened_s = now
        return self.bauds[self.index]

    def heard(self) -> None:
        """A good frame arrived at the current baud."""
        self.locked = True

    def expired(self, now: float) -> bool:
        """True when the port should be closed and opened at the next baud."""
        if self.locked or len(self.bauds) < 2 or self.opened_s is None or now - self.opened_s < PROBE_S:
            return False
        self.index = (self.index + 1) % len(self.bauds)
        self.opened_s = None
        return True

    def closed(self) -> None:
        """The port was lost: the next open probes again, starting at the current baud."""
        self.locked = False
