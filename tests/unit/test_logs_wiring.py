"""Wiring of the flight logs: HEARTBEAT is shared by the control service and the flight logs
(compose.SHARED, both called in order); any other double registration still stops the build."""

from __future__ import annotations

import pytest

from gcsd.compose import DuplicateRegistration, Registry


class Handles:
    """A service that handles the named messages by noting its tag."""

    def __init__(self, seen: list, tag: str, *names: str) -> None:
        self.seen, self.tag, self.names = seen, tag, names

    def message_handlers(self):
        return {name: (lambda inc: self.seen.append(self.tag)) for name in self.names}

    def commands(self):
        return {}


def test_heartbeat_reaches_control_then_logs():
    seen: list = []
    r = Registry()
    r.add("control", Handles(seen, "control", "HEARTBEAT"))
    r.add("logs", Handles(seen, "logs", "HEARTBEAT"))
    r.handlers["HEARTBEAT"](object())
    assert seen == ["control", "logs"]


@pytest.mark.parametrize(("first", "second", "names"), [
    ("control", "logs", ("SYSTEM_TIME",)),  # not shared
    ("logs", "control", ("HEARTBEAT",)),  # shared, but not in this order
])
def test_anything_else_registered_twice_is_still_a_duplicate(first, second, names):
    r = Registry()
    r.add(first, Handles([], first, *names))
    with pytest.raises(DuplicateRegistration):
        r.add(second, Handles([], second, *names))
