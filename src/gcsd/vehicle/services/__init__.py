"""Services of a local MAVLink component. Each declares the messages it handles by naming
methods `handle_<MESSAGE_NAME>` and the commands it handles in `commands()`; the node builds
its dispatch tables from them, so no service is ever reached through an if-chain."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from gcsd.links.channel import Channel
    from gcsd.wire.codec import Frame


@dataclass(frozen=True, slots=True)
class Incoming:
    """A decoded message addressed to us, with where it came from and when."""

    msg: Any
    frame: Frame
    channel: Channel
    now: float

    @property
    def sender(self) -> tuple[int, int]:
        return self.frame.sysid, self.frame.compid


class Service:
    capabilities: int = 0  # MAV_PROTOCOL_CAPABILITY bits this service implements

    def commands(self) -> dict[int, Callable]:
        return {}

    def local_components(self) -> dict[int, dict[int, Callable]]:
        """Other local components this service speaks for: compid -> their command table (the
        camera at compid 100). The router then treats (sysid, compid) as local, and commands
        addressed to it run from that table, ACKed from that compid. Its HEARTBEAT is the
        service's to send (`pending`)."""
        return {}

    def counters(self) -> dict[str, int]:
        """Counted events `gcsd status` shows (summed over a swarm's vehicles), e.g. drops."""
        return {}

    def message_handlers(self) -> dict[str, Callable[[Incoming], None]]:
        return {
            name[len("handle_"):]: getattr(self, name)
            for name in dir(self)
            if name.startswith("handle_") and name[len("handle_"):].isupper()
        }
