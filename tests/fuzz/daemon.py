"""The daemon under fuzz: `gcsd run` as a subprocess (so an exception that escapes is a process
exit), one UDP server channel on loopback, and a raw UDP socket that speaks to it.

`barrier()` proves the daemon read everything sent before it and still serves this link: a
TIMESYNC request with a ts1 of its own must come back echoed. `command()` and `upload()` are a
plain ground station's command and mission upload, used to put the vehicle in flight and to
give it plans; the fuzz itself sends without waiting.
"""

from __future__ import annotations

import json
import os
import select
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as M

from .frames import SOURCE

VEHICLE = (1, 1)
START_TIMEOUT_S = 15.0
BARRIER_TIMEOUT_S = 5.0
ACK_TIMEOUT_S = 2.0


class FuzzedDaemon:
    """`gcsd run` in a subprocess with one UDP server channel, and a raw UDP socket talking to it."""

    def __init__(self, tmp_path: Path, vehicle: str, extra_yaml: str = "", vehicle_keys: str = "") -> None:
        self.config = tmp_path / "gcsd.yaml"
        self.config.write_text(  # port 0: the daemon picks a free port and logs it (no race for a port)
            f"vehicle: {{type: {vehicle}{vehicle_keys}}}\nstate_dir: {tmp_path / 'state'}\n"
            "log: {level: info, format: json}\n"
            "channels:\n  - {name: gcs, type: udp-server, address: '127.0.0.1:0'}\n" + extra_yaml)
        self.log_path = tmp_path / "gcsd.log"
        self._log = self.log_path.open("ab")
        self.sock: socket.socket | None = None
        self.port = 0
        self.mav = M.MAVLink(None, srcSystem=SOURCE[0], srcComponent=SOURCE[1])
        self.mav.robust_parsing = True
        self.barriers = 0
        self.heartbeats: list[float] = []
        self._launch()

    def _launch(self) -> None:
        self._log_start = self.log_path.stat().st_size
        env = dict(os.environ, PATH=str(Path(sys.executable).parent) + os.pathsep + os.environ.get("PATH", ""))
        self.proc = subprocess.Popen([sys.executable, "-m", "gcsd", "run", "-c", str(self.config)],
                                     stdout=self._log, stderr=subprocess.STDOUT, env=env)

    def _opened_port(self) -> int | None:
        """The port of this run's `channel_opened` log record, once it is written."""
        with self.log_path.open("rb") as f:
            f.seek(self._log_start)
            for line in f.read().decode(errors="replace").splitlines():
                if '"channel_opened"' in line:
                    return int(json.loads(line)["address"].rsplit(":", 1)[1])
        return None

    def restart(self) -> int:
        """A clean stop (SIGTERM) and a new start on the same state directory: the stop's exit code."""
        self.proc.send_signal(signal.SIGTERM)
        code = self.proc.wait(10)
        self._launch()
        self.start()
        return code

    # --- io --------------------------------------------------------------------------------------
    def send(self, frame: bytes) -> None:
        try:
            self.sock.send(frame)
        except (BlockingIOError, ConnectionRefusedError):  # a full buffer, or ICMP from a dead port
            pass

    def send_msg(self, msg) -> None:
        self.send(bytes(msg.pack(self.mav)))
        self.mav.seq = (self.mav.seq + 1) % 256

    def read(self, seconds: float) -> list:
        """Messages from the vehicle within `seconds` (returns early once something arrived)."""
        ready, _, _ = select.select([self.sock], [], [], seconds)
        out = []
        while ready:
            try:
                data = self.sock.recv(65536)
            except (BlockingIOError, ConnectionRefusedError):
                break
            for msg in self.mav.parse_buffer(data) or []:
                if msg.get_type() == "BAD_DATA" or (msg.get_srcSystem(), msg.get_srcComponent()) != VEHICLE:
                    continue
                if msg.get_type() == "HEARTBEAT":
                    self.heartbeats.append(time.monotonic())
                out.append(msg)
        return out

    def wait_for(self, match, timeout: float, resend=None, every_s: float = 0.5):
        """The first message matching `match`; `resend()` again every `every_s` while waiting."""
        end = time.monotonic() + timeout
        next_send = 0.0
        while time.monotonic() < end and self.alive():
            if resend is not None and time.monotonic() >= next_send:
                resend()
                next_send = time.monotonic() + every_s
            for msg in self.read(0.05):
                if match(msg):
                    return msg
        return None

    # --- checks ----------------------------------------------------------------------------------
    def alive(self) -> bool:
        return self.proc.poll() is None

    def start(self) -> None:
        """Wait for the channel to open, connect to it and exchange heartbeats."""
        end = time.monotonic() + START_TIMEOUT_S
        port = self._opened_port()
        while port is None and self.alive() and time.monotonic() < end:
            time.sleep(0.05)
            port = self._opened_port()
        assert port is not None, f"the daemon did not open its channel:\n{self.log_tail()}"
        if self.sock is not None:
            self.sock.close()
        self.port = port
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.connect(("127.0.0.1", port))
        self.sock.setblocking(False)
        first = self.wait_for(lambda m: m.get_type() == "HEARTBEAT", START_TIMEOUT_S,
                              resend=lambda: self.send_msg(M.MAVLink_heartbeat_message(
                                  M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)), every_s=0.2)
        assert first is not None, f"the daemon did not come up:\n{self.log_tail()}"

    def barrier(self) -> bool:
        """A TIMESYNC with a ts1 of its own comes back: everything sent before it was read."""
        self.barriers += 1
        ts1 = 7_000_000_000 + self.barriers
        request = M.MAVLink_timesync_message(0, ts1)
        reply = self.wait_for(lambda m: m.get_type() == "TIMESYNC" and m.ts1 == ts1, BARRIER_TIMEOUT_S,
                              resend=lambda: self.send_msg(request))
        return reply is not None

    def param_read_answered(self) -> bool:
        request = M.MAVLink_param_request_read_message(*VEHICLE, b"SYSID_THISMAV", -1)
        reply = self.wait_for(lambda m: m.get_type() == "PARAM_VALUE" and m.param_id == "SYSID_THISMAV",
                              BARRIER_TIMEOUT_S, resend=lambda: self.send_msg(request))
        return reply is not None

    def heartbeat_arrives(self, within_s: float = 2.5) -> bool:
        since = time.monotonic()
        self.wait_for(lambda m: m.get_type() == "HEARTBEAT", within_s)
        return bool(self.heartbeats) and self.heartbeats[-1] >= since

    def log_records(self) -> list[dict]:
        records = []
        for line in self.log_path.read_text(errors="replace").splitlines():
            try:
                records.append(json.loads(line))
            except ValueError:
                records.append({"event": line})
        return records

    def log_tail(self, lines: int = 40) -> str:
        return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])

    def stop(self) -> None:
        if self.alive():
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.sock is not None:
            self.sock.close()
        self._log.close()

    # --- a plain ground station ---------------------------------------------------------------
    def command(self, command: int, *params: float) -> int | None:
        """COMMAND_LONG, resent until its COMMAND_ACK: the result, or None."""
        p = list(params) + [0.0] * (7 - len(params))
        msg = M.MAVLink_command_long_message(*VEHICLE, command, 0, *p)
        ack = self.wait_for(lambda m: m.get_type() == "COMMAND_ACK" and m.command == command, ACK_TIMEOUT_S,
                            resend=lambda: self.send_msg(msg))
        return None if ack is None else ack.result

    def upload(self, mission_type: int, items: list) -> int | None:
        """A plan upload (MISSION_ITEM_INT messages with seq filled in): the MISSION_ACK result, or None."""
        count = M.MAVLink_mission_count_message(*VEHICLE, len(items), mission_type)
        last = count
        self.send_msg(count)
        end = time.monotonic() + 4 * ACK_TIMEOUT_S
        while time.monotonic() < end and self.alive():
            got = self.wait_for(lambda m: m.get_type() in ("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK")
                                and m.mission_type == mission_type and m.target_system == SOURCE[0], 0.5)
            if got is None:
                self.send_msg(last)
            elif got.get_type() == "MISSION_ACK":
                return got.type
            elif got.seq < len(items):
                last = items[got.seq]
                last.seq = got.seq
                self.send_msg(last)
        return None

    def param_names(self) -> list[str]:
        """Every parameter name, read by index (PARAM_REQUEST_READ, 100 in flight; a list download is
        paced, reads are not)."""
        first = self.wait_for(lambda m: m.get_type() == "PARAM_VALUE" and m.param_index == 0, BARRIER_TIMEOUT_S,
                              resend=lambda: self.send_msg(M.MAVLink_param_request_read_message(*VEHICLE, b"", 0)))
        assert first is not None, "PARAM_REQUEST_READ of index 0 not answered"
        count = first.param_count
        names: dict[int, str] = {0: first.param_id}
        end = time.monotonic() + 20.0
        while len(names) < count and time.monotonic() < end:
            batch = [i for i in range(count) if i not in names][:100]
            for i in batch:
                self.send_msg(M.MAVLink_param_request_read_message(*VEHICLE, b"", i))
            quiet = time.monotonic() + 0.3
            while time.monotonic() < quiet and not all(i in names for i in batch):
                for m in self.read(0.05):
                    if m.get_type() == "PARAM_VALUE" and m.param_index < count and m.param_index not in names:
                        names[m.param_index] = m.param_id
                        quiet = time.monotonic() + 0.3
        assert len(names) == count, f"parameter names: {len(names)} of {count}"
        return [names[i] for i in range(count)]

    def soak(self, seconds: float) -> None:
        """Let the simulation and telemetry run for a while on whatever state the fuzz left."""
        end = time.monotonic() + seconds
        while time.monotonic() < end and self.alive():
            self.read(0.05)
