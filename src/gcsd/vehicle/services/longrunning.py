"""The long-running command slot (ArduPilot's GCS_MAVLINK_InProgress), pure.

One slot per vehicle. `start` answers IN_PROGRESS at once (the caller's handler returns it);
while the work runs, a further COMMAND_ACK IN_PROGRESS goes to the requester at most once a
second (progress in percent: MAVLink's meaning; ArduPilot sends 0); when its time is up the
`finish` function runs and its MAV_RESULT is the final ACK, to the original requester on the
original channel. A second long-running command while the slot is busy gets
TEMPORARILY_REJECTED. Durations are real seconds: calibrating does not go faster with speedup.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as M

PROGRESS_INTERVAL_S = 1.0


@dataclass
class Job:
    command: int
    requester: tuple[int, int]
    channel: object
    started_s: float
    finish_s: float
    finish: Callable[[], int]
    next_progress_s: float


class LongRunning:
    def __init__(self) -> None:
        self.job: Job | None = None

    def start(self, command: int, requester: tuple[int, int], channel, now: float, duration_s: float,
              finish: Callable[[], int]) -> int:
        if self.job is not None:
            return M.MAV_RESULT_TEMPORARILY_REJECTED
        self.job = Job(command, requester, channel, now, now + duration_s, finish, now + PROGRESS_INTERVAL_S)
        return M.MAV_RESULT_IN_PROGRESS

    def due(self, channel, now: float) -> list:
        """COMMAND_ACKs to send on `channel` now (progress or final)."""
        job = self.job
        if job is None or job.channel is not channel:
            return []
        if now >= job.finish_s:
            self.job = None
            return [self._ack(job, job.finish(), 100)]
        if now >= job.next_progress_s:
            job.next_progress_s += PROGRESS_INTERVAL_S
            span = max(job.finish_s - job.started_s, 1e-6)
            return [self._ack(job, M.MAV_RESULT_IN_PROGRESS, int(100 * (now - job.started_s) / span))]
        return []

    def next_deadline(self) -> float | None:
        job = self.job
        return None if job is None else min(job.finish_s, job.next_progress_s)

    @staticmethod
    def _ack(job: Job, result: int, progress: int):
        return M.MAVLink_command_ack_message(job.command, result, max(0, min(100, progress)), 0, *job.requester)
