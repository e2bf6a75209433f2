"""The CAN buses of `can.buses`, through python-can: non-blocking reads and writes.

`open_bus(config)` opens one python-can bus (`virtual`: an in-process bus that every bus object
on the same channel name shares, where the simulated DroneCAN nodes live; `socketcan`: a Linux
CAN interface such as can0 or vcan0). A bus that cannot be opened at start is a startup failure
naming it (`CanBusError`), never a daemon that sits there half-working. Frames are converted at
this edge: MAVLink's CAN id carries bit 31 for an extended id (AP_HAL's CANFrame::FlagEFF),
python-can a separate flag. Reads take at most `limit` frames per call so one busy bus cannot
hold the event loop; a write the interface refuses (its queue full, bus-off) is counted, not raised.
"""

from __future__ import annotations

import can

from gcsd.config.can import CanBusConfig
from gcsd.links.transport import ChannelStartError
from gcsd.payloads.can.forward import EXTENDED_FLAG, CanFrame

ID_MASK = 0x1FFFFFFF


class CanBusError(ChannelStartError):
    """A configured bus that cannot be opened: a start failure, one clear line (as a server channel's)."""


class CanBus:
    def __init__(self, index: int, config: CanBusConfig) -> None:
        self.index = index
        self.config = config
        self.write_errors = 0
        self.frames_in = 0
        self.frames_out = 0
        try:
            self.bus = can.Bus(interface=config.interface, channel=config.channel, fd=config.fd,
                               receive_own_messages=False)
        except (OSError, can.CanError, ValueError) as exc:
            raise CanBusError(f"can bus {index} ({config.interface} {config.channel}): {exc}") from exc

    def poll(self, limit: int = 64) -> list[CanFrame]:
        frames = []
        while len(frames) < limit:
            msg = self.bus.recv(0)
            if msg is None or msg.is_error_frame or msg.is_remote_frame:
                if msg is None:
                    break
                continue
            can_id = msg.arbitration_id | (EXTENDED_FLAG if msg.is_extended_id else 0)
            frames.append(CanFrame(self.index, can_id, bytes(msg.data), bool(msg.is_fd)))
        self.frames_in += len(frames)
        return frames

    def send(self, frame: CanFrame) -> bool:
        msg = can.Message(arbitration_id=frame.can_id & ID_MASK, is_extended_id=bool(frame.can_id & EXTENDED_FLAG),
                          data=frame.data, is_fd=frame.fd)
        try:
            self.bus.send(msg, timeout=0)
        except (can.CanError, OSError, ValueError):
            self.write_errors += 1
            return False
        self.frames_out += 1
        return True

    def close(self) -> None:
        self.bus.shutdown()
