"""Message filters per channel (SPEC.md "Companion routing", `filter`), compiled for one cheap
check per frame, and the gates a channel calls on its receive and write paths.

A `FrameFilter` is compiled from one direction's `FilterRules` (config_companion.py): a frame
passes when, for each of message id, source system and source component, the allow list (if
any) names it and the block list does not. The answer for each (msgid, sysid, compid) is
memoised in a dict keyed by one integer, so the steady state costs one dict lookup per frame;
the memo holds at most MEMO_MAX answers and is cleared when full.

`InGate.allow(frame)`: after the signature check, before routing and local handling.
`OutGate.allow(raw, now)`: everything written to the channel, forwarded or our own: the out
filter, then the rate caps (ratecap.py). The header is read from the raw bytes (MAVLink1 or 2).
A channel with neither filter nor caps has no gate at all (`None`), so it pays nothing.
Counters: `filtered` (each gate), `RateCaps.limited`.
"""

from __future__ import annotations

from .config import ChannelConfig
from .config_companion import FilterRules
from .ratecap import RateCaps

MEMO_MAX = 65536
STX_V2 = 0xFD


def header(raw: bytes) -> tuple[int, int, int]:
    """(msgid, sysid, compid) of a whole MAVLink1 or MAVLink2 frame."""
    if raw[0] == STX_V2:
        return raw[7] | raw[8] << 8 | raw[9] << 16, raw[5], raw[6]
    return raw[5], raw[3], raw[4]


class FrameFilter:
    __slots__ = ("_memo", "_tests")

    def __init__(self, rules: FilterRules) -> None:
        tests = []
        for shift, allow, block in ((16, rules.allow_msgids, rules.block_msgids),
                                    (8, rules.allow_src_sys, rules.block_src_sys),
                                    (0, rules.allow_src_comp, rules.block_src_comp)):
            if allow is not None:
                tests.append((shift, allow, True))
            if block:
                tests.append((shift, block, False))
        self._tests = tuple(tests)
        self._memo: dict[int, bool] = {}

    def passes(self, msgid: int, sysid: int, compid: int) -> bool:
        key = msgid << 16 | sysid << 8 | compid
        answer = self._memo.get(key)
        if answer is None:
            fields = {16: msgid, 8: sysid, 0: compid}
            answer = all((fields[shift] in values) == allow for shift, values, allow in self._tests)
            if len(self._memo) >= MEMO_MAX:
                self._memo.clear()
            self._memo[key] = answer
        return answer


class InGate:
    __slots__ = ("_filter", "filtered")

    def __init__(self, rules: FilterRules) -> None:
        self._filter = FrameFilter(rules)
        self.filtered = 0

    def allow(self, frame) -> bool:
        if self._filter.passes(frame.msgid, frame.sysid, frame.compid):
            return True
        self.filtered += 1
        return False


class OutGate:
    __slots__ = ("_filter", "caps", "filtered")

    def __init__(self, rules: FilterRules, caps: RateCaps) -> None:
        self._filter = None if rules.empty else FrameFilter(rules)
        self.caps = caps
        self.filtered = 0

    def allow(self, raw: bytes, now: float) -> bool:
        msgid, sysid, compid = header(raw)
        return self.allow_header(msgid, sysid, compid, now)

    def allow_header(self, msgid: int, sysid: int, compid: int, now: float) -> bool:
        if self._filter is not None and not self._filter.passes(msgid, sysid, compid):
            self.filtered += 1
            return False
        return self.caps.allow(msgid, sysid, compid, now)


def gates(config: ChannelConfig) -> tuple[InGate | None, OutGate | None]:
    """A channel's gates; None where its configuration asks for nothing."""
    inbound = None if config.filter.inbound.empty else InGate(config.filter.inbound)
    caps = RateCaps(config.rate_limits)
    outbound = None if config.filter.outbound.empty and not caps else OutGate(config.filter.outbound, caps)
    return inbound, outbound


def counters(inbound: InGate | None, outbound: OutGate | None) -> dict[str, int]:
    return {"filtered_in": inbound.filtered if inbound else 0,
            "filtered_out": outbound.filtered if outbound else 0,
            "rate_limited": outbound.caps.limited if outbound else 0}
