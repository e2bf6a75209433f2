"""Test helpers for missions: a careful pymavlink ground station and a seeded lossy UDP proxy.

`MissionClient` speaks the GCS side of the mission protocol over a `helpers.Client` and
retries as a good ground station does on a lossy link:
- upload: MISSION_COUNT, then each requested item (MISSION_REQUEST or _INT); when nothing comes
  for `timeout_s` it sends again what it sent last (the count, or the last item: a lost final
  ACK is recovered by the vehicle's re-ACK of a repeated final item);
- download: MISSION_REQUEST_LIST until MISSION_COUNT, then up to `window` MISSION_REQUEST_INT in
  flight, each asked again after `timeout_s`, then the final MISSION_ACK.
Both give up after `deadline_s` with an AssertionError that says how far they got.

`LossyProxy` is a UDP relay in a thread between one client and the daemon's UDP port: each
datagram is dropped with probability `loss` in each direction, decided by its own
`random.Random(seed)` per direction, so a run's drop pattern depends only on the seed and the
order of datagrams.
"""

from __future__ import annotations

import random
import select
import socket
import threading
import time

from pymavlink.dialects.v20 import ardupilotmega as M

from gcsd.vehicle.mission.items import MissionItem, from_item_int

from .helpers import VEHICLE, Client


class MissionClient:
    def __init__(self, client: Client, target: tuple[int, int] = VEHICLE, timeout_s: float = 0.25,
                 window: int = 5, deadline_s: float = 60.0) -> None:
        self.c = client
        self.target = target
        self.timeout_s = timeout_s
        self.window = window
        self.deadline_s = deadline_s
        self.resent = 0

    def _from_vehicle(self, r, name: str, mission_type: int) -> bool:
        return (r.type == name and r.src == self.target and getattr(r.msg, "mission_type", 0) == mission_type
                and getattr(r.msg, "target_system", self.c.sysid) == self.c.sysid)

    def _next(self, mark: int, wanted: tuple[str, ...], mission_type: int, timeout_s: float):
        """The first wanted message after `mark` within timeout_s: (record, new mark) or (None, mark)."""
        end = time.monotonic() + timeout_s
        while True:
            for i in range(mark, len(self.c.received)):
                r = self.c.received[i]
                if any(self._from_vehicle(r, name, mission_type) for name in wanted):
                    return r, i + 1
            mark = len(self.c.received)
            left = end - time.monotonic()
            if left <= 0:
                return None, mark
            ready, _, _ = select.select([self.c], [], [], min(left, 0.05))
            if ready:
                self.c.read_available()

    def upload(self, items: list[MissionItem], mission_type: int = 0, use_int: bool = True) -> int:
        """Upload a plan; returns the MISSION_ACK result."""
        ts, tc = self.target
        count_msg = M.MAVLink_mission_count_message(ts, tc, len(items), mission_type)
        mark = self.c.mark()
        last = count_msg
        self.c.send(last)
        started = time.monotonic()
        highest = -1
        while time.monotonic() - started < self.deadline_s:
            wanted = ("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK")
            r, mark = self._next(mark, wanted, mission_type, self.timeout_s)
            if r is None:
                self.resent += 1
                self.c.send(last)
                continue
            if r.type == "MISSION_ACK":
                self._next(mark, ("MISSION_ACK",), mission_type, 0.05)  # gcsd sends the final ACK twice:
                return r.msg.type  # read the copy now, so that the next exchange does not take it
            seq = r.msg.seq
            highest = max(highest, seq)
            it = items[seq]
            if use_int:
                last = M.MAVLink_mission_item_int_message(
                    ts, tc, seq, it.frame, it.command, it.current, it.autocontinue, it.param1, it.param2,
                    it.param3, it.param4, it.x, it.y, it.z, mission_type)
            else:
                last = M.MAVLink_mission_item_message(
                    ts, tc, seq, it.frame, it.command, it.current, it.autocontinue, it.param1, it.param2,
                    it.param3, it.param4, it.x / 1e7, it.y / 1e7, it.z, mission_type)
            self.c.send(last)
        raise AssertionError(f"upload of {len(items)} items not acknowledged in {self.deadline_s} s; "
                             f"highest item requested {highest}, {self.resent} resends")

    def download(self, mission_type: int = 0) -> list[MissionItem]:
        ts, tc = self.target
        started = time.monotonic()
        mark = self.c.mark()
        count = None
        while count is None:
            if time.monotonic() - started > self.deadline_s:
                raise AssertionError(f"no MISSION_COUNT in {self.deadline_s} s")
            self.c.send(M.MAVLink_mission_request_list_message(ts, tc, mission_type))
            r, mark = self._next(mark, ("MISSION_COUNT", "MISSION_ACK"), mission_type, self.timeout_s)
            if r is not None and r.type == "MISSION_ACK" and r.msg.type != M.MAV_MISSION_ACCEPTED:
                raise AssertionError(f"download refused with MISSION_ACK {r.msg.type}")
            if r is not None and r.type == "MISSION_ACK":
                continue  # a late copy of an upload's final ACK: not an answer to this request
            if r is not None:
                count = r.msg.count
        got: dict[int, MissionItem] = {}
        asked: dict[int, float] = {}
        while len(got) < count:
            if time.monotonic() - started > self.deadline_s:
                raise AssertionError(f"download: {len(got)} of {count} items in {self.deadline_s} s")
            now = time.monotonic()
            for seq in [s for s in range(count) if s not in got][: self.window]:
                if now - asked.get(seq, -1e9) >= self.timeout_s:
                    if seq in asked:
                        self.resent += 1
                    asked[seq] = now
                    self.c.send(M.MAVLink_mission_request_int_message(ts, tc, seq, mission_type))
            r, mark = self._next(mark, ("MISSION_ITEM_INT",), mission_type, 0.02)
            while r is not None:
                got.setdefault(r.msg.seq, from_item_int(r.msg))
                r, mark = self._next(mark, ("MISSION_ITEM_INT",), mission_type, 0.0)
        self.c.send(M.MAVLink_mission_ack_message(ts, tc, M.MAV_MISSION_ACCEPTED, mission_type))
        return [got[s] for s in range(count)]

    def clear(self, mission_type: int = 0) -> int:
        ts, tc = self.target
        mark = self.c.mark()
        for _ in range(int(self.deadline_s / self.timeout_s)):
            self.c.send(M.MAVLink_mission_clear_all_message(ts, tc, mission_type))
            r, mark = self._next(mark, ("MISSION_ACK",), mission_type, self.timeout_s)
            if r is not None:
                return r.msg.type
        raise AssertionError("no MISSION_ACK to MISSION_CLEAR_ALL")


class LossyProxy:
    """UDP relay 127.0.0.1:`port` <-> 127.0.0.1:`upstream_port`, dropping `loss` of each direction."""

    def __init__(self, upstream_port: int, loss: float, seed: int = 1) -> None:
        self.upstream = ("127.0.0.1", upstream_port)
        self.loss = loss
        self._rng_up = random.Random(seed)
        self._rng_down = random.Random(seed + 1)
        self._front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._front.bind(("127.0.0.1", 0))
        self._back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._back.bind(("127.0.0.1", 0))
        self.port = self._front.getsockname()[1]
        self._client: tuple[str, int] | None = None
        self.forwarded = {"up": 0, "down": 0}
        self.dropped = {"up": 0, "down": 0}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lossy-proxy", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        socks = [self._front, self._back]
        while not self._stop.is_set():
            ready, _, _ = select.select(socks, [], [], 0.05)
            for sock in ready:
                try:
                    data, addr = sock.recvfrom(65536)
                except OSError:
                    continue
                if sock is self._front:
                    self._client = addr
                    self._relay("up", self._rng_up, data, self._back, self.upstream)
                elif self._client is not None:
                    self._relay("down", self._rng_down, data, self._front, self._client)

    def _relay(self, way: str, rng: random.Random, data: bytes, out: socket.socket, to) -> None:
        if rng.random() < self.loss:
            self.dropped[way] += 1
            return
        self.forwarded[way] += 1
        try:
            out.sendto(data, to)
        except OSError:
            pass

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)
        self._front.close()
        self._back.close()
