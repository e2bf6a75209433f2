"""MAVLink FTP service: the thin adapter between the node and the pure FtpServer (gcsd.vehicle.ftp).

- FILE_TRANSFER_PROTOCOL requests go to `FtpServer.handle`; its replies are sent at once on
  the requesting link, targeted at the requester (target_network 0), while the link's byte
  budget has room; what does not fit waits in a per-link outbox of OUTBOX_MAX replies (older
  ones are dropped and counted beyond that: the client retries).
- Bursts and long CRCs go out in the node's send pass (`pending`) when the server says they
  are due (it paces bursts itself, see ftp/burst.py): at most PACKETS_PER_PASS per pass (then
  the pass yields to the event loop), and on a link with a configured bandwidth no more than a
  third of it, as ArduPilot paces bursts (3 x packet bytes / bandwidth between packets), so a
  radio link keeps room for telemetry and for the client's requests.
- Any FTP reply slows the link's streams x4 for SLOW_S (1 s), as ArduPilot does.
- The FTP root is `ftp.root` under the vehicle's state directory; writes stop at
  `ftp.max_file_bytes`. `mounts` adds directories kept elsewhere (the flight logs as `logs/`).
  Virtual files: `@PARAM/param.pck` through the node's parameter store
  and parameter service, `@MISSION/*.dat` through its mission service.
"""

from __future__ import annotations

from collections import deque
from pathlib import Path

import structlog
from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.links.channel import MAX_FRAME_BYTES
from gcsd.vehicle.ftp.fs import ConfinedFs
from gcsd.vehicle.ftp.mission_files import MissionFiles
from gcsd.vehicle.ftp.server import FtpServer, Outgoing
from gcsd.vehicle.ftp.virtual import VirtualFiles
from gcsd.vehicle.services import Incoming, Service

log = structlog.get_logger("gcsd.vehicle.ftp")

OUTBOX_MAX = 64
PACKETS_PER_PASS = 32
SLOW_S = 1.0
BURST_BANDWIDTH_SHARE = 3  # a burst uses at most 1/3 of a link's configured bandwidth


class VehicleParams:
    """The vehicle's parameter store and service, as the FTP virtual files want them."""

    def __init__(self, ctx, param_service) -> None:
        self.ctx = ctx
        self.param_service = param_service

    def entries(self):
        return self.ctx.params.entries()

    def count(self) -> int:
        return len(self.ctx.params)

    def set_from_file(self, name: str, value: float) -> bool:
        return self.param_service.set_from_file(name, value, save=False)

    def commit(self) -> None:
        self.ctx.save_params()

    def downloaded(self) -> None:
        self.ctx.banner()


class FtpService(Service):
    capabilities = M.MAV_PROTOCOL_CAPABILITY_FTP

    def __init__(self, ctx, root: Path, max_file_bytes: int, param_service=None, plans=None,
                 mounts: dict[str, Path] | None = None) -> None:
        """`param_service` serves @PARAM/param.pck, `plans` (the mission service: read_plan /
        write_plan) the @MISSION files; without them those virtual files do not exist. `mounts`: directories kept
        elsewhere (the flight logs as `logs/`)."""
        self.ctx = ctx
        params = VehicleParams(ctx, param_service) if param_service is not None else None
        missions = MissionFiles(plans) if plans is not None else None
        self.server = FtpServer(ConfinedFs(root, max_file_bytes, mounts), VirtualFiles(params, missions))
        self._outbox: dict[int, deque[Outgoing]] = {}
        self._slow_until_s: dict[int, float] = {}
        self._next_burst_s: dict[int, float] = {}
        self.replies_dropped = 0
        log.info("ftp_root_opened", root=str(self.server.fs.root), max_file_bytes=max_file_bytes)

    def counters(self) -> dict[str, int]:
        return {"ftp_replies_dropped": self.replies_dropped}

    def handle_FILE_TRANSFER_PROTOCOL(self, inc: Incoming) -> None:
        channel = inc.channel
        replies = self.server.handle(bytes(inc.msg.payload), inc.sender, channel.index, inc.now)
        box = self._outbox.setdefault(channel.index, deque())
        for reply in replies:
            if len(box) >= OUTBOX_MAX:
                box.popleft()
                self.replies_dropped += 1
            box.append(reply)
        self._flush(channel, inc.now, lambda msg: self.ctx.reply(channel, msg))
        if box or self.server.has_work(channel.index):
            self.ctx.wake(channel)

    def pending(self, channel, now: float, send) -> float | None:
        """The send-pass hook: outbox, then bursts and CRCs; returns this service's next deadline."""
        index = channel.index
        self.server.expire(now)
        gate = None  # when the link can take FTP packets again, if it cannot now
        if not self._flush(channel, now, send):
            gate = now + max(channel.budget_wait_s(MAX_FRAME_BYTES), 0.001)
        elif self.server.has_work(index):
            gate = self._pump(channel, now, send)
        deadline = self.server.next_deadline(now, index)
        if gate is not None:
            deadline = gate if deadline is None else max(deadline, gate)
        until = self._slow_until_s.get(index)
        if until is not None and now >= until:
            del self._slow_until_s[index]
            self.ctx.link(channel).set_slow("ftp", False)
        elif until is not None:
            deadline = until if deadline is None else min(deadline, until)
        return deadline

    # --- sending ---------------------------------------------------------------------------
    def _flush(self, channel, now: float, send) -> bool:
        """Send queued replies while there is room; True when the outbox is empty."""
        box = self._outbox.get(channel.index)
        while box:
            if not channel.has_room(MAX_FRAME_BYTES) or not self._send(channel, box[0], now, send):
                return False
            box.popleft()
        return True

    def _pump(self, channel, now: float, send) -> float | None:
        """Burst packets that are due, within the pass limit and the link's budget."""
        index = channel.index
        bandwidth = channel.config.bandwidth
        sent = 0
        while sent < PACKETS_PER_PASS:
            if bandwidth and self._next_burst_s.get(index, 0.0) > now:
                return self._next_burst_s[index]
            if not channel.has_room(MAX_FRAME_BYTES):
                return now + max(channel.budget_wait_s(MAX_FRAME_BYTES), 0.001)
            packets = self.server.pump(index, now, 1 if bandwidth else PACKETS_PER_PASS - sent)
            if not packets:
                return None  # nothing due now: the server's deadline says when
            for i, packet in enumerate(packets):
                if not self._send(channel, packet, now, send):
                    self._outbox.setdefault(index, deque()).extend(packets[i:])  # not lost: sent next pass
                    return now + 0.001
            sent += len(packets)
            if bandwidth:
                start = max(self._next_burst_s.get(index, 0.0), now)
                gap_s = BURST_BANDWIDTH_SHARE * len(packets[0].payload) / bandwidth
                self._next_burst_s[index] = start + gap_s
        return now

    def _send(self, channel, out: Outgoing, now: float, send) -> bool:
        msg = M.MAVLink_file_transfer_protocol_message(0, out.target[0], out.target[1], out.payload)
        if not send(msg):
            return False
        if channel.index not in self._slow_until_s:
            self.ctx.link(channel).set_slow("ftp", True)
        self._slow_until_s[channel.index] = now + SLOW_S
        return True
