"""A channel's receiver for the channel tests: records what the channel hands on."""

from __future__ import annotations

from gcsd.links.channel import Unwired


class Recorder(Unwired):
    """Accepts every frame (or refuses each with `verdict`) and keeps what it is given."""

    def __init__(self, verdict: str | None = None) -> None:
        self.verdict = verdict
        self.frames: list = []
        self.rejects: list[str] = []

    def verify(self, channel, frame) -> str | None:
        return self.verdict

    def on_frame(self, channel, frame, now: float) -> None:
        self.frames.append(frame)

    def on_reject(self, channel, frame, reason: str, now: float) -> None:
        self.rejects.append(reason)
