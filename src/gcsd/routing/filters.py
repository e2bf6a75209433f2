"""Message filters per channel (SPEC.md "Companion routing", `filter`), compiled for one cheap
check per frame, and the gates a channel calls on its receive and write paths.

A `FrameFilter` is compiled from one direction's `FilterRules` (config_companion.py): a frame
passes when, for each of message id, source system and source component, the allow list (if
any) names it and the block list does not. The answer for each (msgid, sysid, compid) is
memoised in a dict keyed by one integer, so the steady state costs one dict lookup per frame;
the memo holds at most MEMO_MAX answers and is cleared when full.

`InGate.allow(frame)`: after the signature check, before routing and local handling.
`OutGate.allow(raw, clock)`: everything written to the channel, forwarded or our own: the out
filter, then the rate caps (ratecap.py), memoised together as one verdict per (msgid, sysid,
compid), so a frame costs one header read and one dict lookup (the clock is read only for a
capped message). The header is read from the raw bytes (MAVLink1 or 2).
A channel with neither filter nor caps has no gate at all (`None`), so it pays nothing.
Counters: `filtered` (each gate), `RateCaps.limited`.
"""

from __future__ import annotations

from gcsd.config import ChannelConfig
from gcsd.config.companion import FilterRules
from gcsd.routing.ratecap import RateCaps

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
        return self.passes_key(msgid << 16 | sysid << 8 | compid)

    def passes_key(self, key: int) -> bool:
        """`key` is msgid << 16 | sysid << 8 | compid."""
        answer = self._memo.get(key)
        if answer is None:
            answer = all((((key >> shift) & (0xFFFFFF if shift == 16 else 0xFF)) in values) == allow
                         for shift, values, allow in self._tests)
            if len(self._memo) >= MEMO_MAX:
                self._memo.clear()
            self._memo[key] = answer
        return answer


class InGate:
    __slots__ = ("_memo", "_passes", "filtered")

    def __init__(self, rules: FilterRules) -> None:
        f = FrameFilter(rules)
        self._memo, self._passes = f._memo, f.passes_key
        self.filtered = 0

    def allow(self, frame) -> bool:
        key = frame.msgid << 16 | frame.sysid << 8 | frame.compid
        answer = self._memo.get(key)
        if answer is None:
            answer = self._passes(key)
        if not answer:
            self.filtered += 1
        return answer


class OutGate:
    """filter.out and the rate caps as one memoised verdict per (msgid, sysid, compid): True
    (passes), False (filtered) or the cap's period (the rate cap decides, with the clock)."""

    __slots__ = ("_filter", "_verdicts", "caps", "filtered")

    def __init__(self, rules: FilterRules, caps: RateCaps) -> None:
        self._filter = None if rules.empty else FrameFilter(rules)
        self.caps = caps
        self._verdicts: dict[int, bool | float] = {}
        self.filtered = 0

    def allow(self, raw: bytes, clock) -> bool:
        """A whole frame about to be written; `clock()` is read only for a capped message."""
        if raw[0] == STX_V2:
            return self.allow_key((raw[7] | raw[8] << 8 | raw[9] << 16) << 16 | raw[5] << 8 | raw[6], clock)
        return self.allow_key(raw[5] << 16 | raw[3] << 8 | raw[4], clock)

    def allow_key(self, key: int, clock) -> bool:
        """`key` is msgid << 16 | sysid << 8 | compid (our own messages: before they are encoded)."""
        verdict = self._verdicts.get(key)
        if verdict is None:
            verdict = self._verdict(key)
        if verdict is True:
            return True
        if verdict is False:
            self.filtered += 1
            return False
        return self.caps.allow_key(key, verdict, clock())

    def _verdict(self, key: int) -> bool | float:
        if self._filter is not None and not self._filter.passes_key(key):
            verdict = False
        else:
            period = self.caps.period_s(key >> 16)
            verdict = True if period is None else period
        if len(self._verdicts) >= MEMO_MAX:
            self._verdicts.clear()
        self._verdicts[key] = verdict
        return verdict


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
