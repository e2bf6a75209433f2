"""Stream requests on behalf of ground stations that never ask (SPEC.md "Companion routing",
`request_streams: N`, as mavp2p's --streamreq). Pure: frames and `now` in, requests out.

Per channel with request_streams > 0, each autopilot learned on it (a HEARTBEAT whose autopilot
is not MAV_AUTOPILOT_INVALID and whose type is not a GCS) is asked for all its streams at N Hz
(REQUEST_DATA_STREAM, MAV_DATA_STREAM_ALL, start): when first heard; again when it has rebooted,
seen as its SYSTEM_TIME.time_boot_ms going back, or its HEARTBEAT returning after SILENCE_S.
States per autopilot (sysid, compid): unknown -> requested(last heartbeat, last boot time).
At most MAX_AUTOPILOTS are tracked (the silent longest is forgotten first).
"""

from __future__ import annotations

MSG_ID_HEARTBEAT = 0
MSG_ID_SYSTEM_TIME = 2
MAV_AUTOPILOT_INVALID = 8
MAV_TYPE_GCS = 6
SILENCE_S = 5.0
MAX_AUTOPILOTS = 64


class StreamRequests:
    __slots__ = ("_autopilots", "rate_hz", "sent")

    def __init__(self, rate_hz: int) -> None:
        self.rate_hz = rate_hz
        self._autopilots: dict[tuple[int, int], list[float]] = {}  # -> [last heartbeat s, last boot ms]
        self.sent = 0

    def heartbeat(self, sysid: int, compid: int, mav_type: int, autopilot: int, now: float) -> bool:
        """True when (sysid, compid) should be asked for its streams now."""
        if autopilot == MAV_AUTOPILOT_INVALID or mav_type == MAV_TYPE_GCS:
            return False
        key = (sysid, compid)
        state = self._autopilots.get(key)
        if state is None:
            if len(self._autopilots) >= MAX_AUTOPILOTS:
                del self._autopilots[min(self._autopilots, key=lambda k: self._autopilots[k][0])]
            self._autopilots[key] = [now, -1.0]
            return self._request()
        silent = now - state[0] > SILENCE_S
        state[0] = now
        return self._request() if silent else False

    def system_time(self, sysid: int, compid: int, time_boot_ms: int) -> bool:
        """True when an autopilot's boot time went back: it rebooted, ask again."""
        state = self._autopilots.get((sysid, compid))
        if state is None:
            return False
        rebooted = 0 <= time_boot_ms < state[1]
        state[1] = time_boot_ms
        return self._request() if rebooted else False

    def _request(self) -> bool:
        self.sent += 1
        return True
