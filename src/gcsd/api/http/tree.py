"""The message tree of `GET /v1/mavlink`: every system's last message of each name.

Shape (mavlink2rest's `src/data.rs`): `{"vehicles": {"SYSID": {"id": SYSID, "components":
{"COMPID": {"id": COMPID, "messages": {NAME: ENTRY}}}}}}`, an ENTRY being
`{"message": {...}, "status": {"time": {"counter", "first_update", "frequency", "last_update"}}}`.
counter counts the messages of that name from that component (1 at the first); first_update
and last_update are ISO 8601 with the local zone; frequency = counter / seconds since the first
(0.0 within the first instant). Any sub-path is served like a JSON pointer
(`vehicles/1/components/1/messages/ATTITUDE/message/roll`); a path that names nothing is
`KeyError` (gcsd answers 404 where mavlink2rest answers 200 "None").

An update stores the pymavlink message, or the received Frame, as it is; a Frame is decoded and
anything converted to JSON only when a path reaches it, so a routed frame nobody reads costs a
dictionary store and no decoding. Bounded: at most
MAX_COMPONENTS (sysid, compid) pairs (a peer inventing sources gets nothing more; counted in
`components_refused`); names are the dialect's, so each component holds at most one entry per
message type. Time is passed in (`wall_s`, seconds since the epoch); nothing here reads a clock.
"""

from __future__ import annotations

from datetime import UTC, datetime

from gcsd.api.http.mavjson import message_json
from gcsd.wire.codec import Frame

MAX_COMPONENTS = 512


def iso_time(wall_s: float) -> str:
    return datetime.fromtimestamp(wall_s, UTC).astimezone().isoformat()


class Entry:
    __slots__ = ("counter", "first_s", "last_s", "msg")

    def __init__(self, msg, wall_s: float) -> None:
        self.msg = msg
        self.counter = 1
        self.first_s = wall_s
        self.last_s = wall_s

    def status(self) -> dict:
        elapsed = self.last_s - self.first_s
        return {"time": {
            "counter": self.counter,
            "first_update": iso_time(self.first_s),
            "frequency": self.counter / elapsed if elapsed > 0 else 0.0,
            "last_update": iso_time(self.last_s),
        }}

    def message(self):
        msg = self.msg
        return msg.msg if isinstance(msg, Frame) else msg

    def document(self) -> dict:
        return {"message": message_json(self.message()), "status": self.status()}


class MessageTree:
    def __init__(self, max_components: int = MAX_COMPONENTS) -> None:
        self._systems: dict[int, dict[int, dict[str, Entry]]] = {}
        self._components = 0
        self.max_components = max_components
        self.components_refused = 0

    def update(self, sysid: int, compid: int, name: str, msg, wall_s: float) -> None:
        """`msg`: a pymavlink message or a Frame of a known message id, decoded when read."""
        components = self._systems.get(sysid)
        messages = components.get(compid) if components is not None else None
        if messages is None:
            if self._components >= self.max_components:
                self.components_refused += 1
                return
            self._components += 1
            messages = self._systems.setdefault(sysid, {}).setdefault(compid, {})
        entry = messages.get(name)
        if entry is None:
            messages[name] = Entry(msg, wall_s)
            return
        entry.msg = msg
        entry.counter += 1
        entry.last_s = wall_s

    def entry(self, sysid: int, compid: int, name: str) -> Entry | None:
        return self._systems.get(sysid, {}).get(compid, {}).get(name)

    def systems(self) -> dict[int, dict[int, dict[str, Entry]]]:
        return self._systems

    # --- documents -------------------------------------------------------------------------
    def document(self, parts: list[str]) -> object:
        """The JSON value at a path (its parts, already split on '/'); KeyError if none."""
        if not parts:
            return {"vehicles": self._vehicles()}
        head, rest = parts[0], parts[1:]
        if head != "vehicles":
            raise KeyError(head)
        if not rest:
            return self._vehicles()
        components = self._systems[_id(rest[0])]
        sysid = int(rest[0])
        rest = rest[1:]
        if not rest:
            return self._vehicle(sysid, components)
        if rest[0] == "id":
            return _leaf(sysid, rest[1:])
        if rest[0] != "components":
            raise KeyError(rest[0])
        rest = rest[1:]
        if not rest:
            return self._components_doc(components)
        messages = components[_id(rest[0])]
        compid = int(rest[0])
        rest = rest[1:]
        if not rest:
            return self._component(compid, messages)
        if rest[0] == "id":
            return _leaf(compid, rest[1:])
        if rest[0] != "messages":
            raise KeyError(rest[0])
        rest = rest[1:]
        if not rest:
            return {name: e.document() for name, e in messages.items()}
        entry = messages[rest[0]]
        return _pointer(entry.document(), rest[1:])

    def _vehicles(self) -> dict:
        return {str(s): self._vehicle(s, c) for s, c in self._systems.items()}

    def _vehicle(self, sysid: int, components: dict) -> dict:
        return {"id": sysid, "components": self._components_doc(components)}

    def _components_doc(self, components: dict) -> dict:
        return {str(c): self._component(c, m) for c, m in components.items()}

    @staticmethod
    def _component(compid: int, messages: dict) -> dict:
        return {"id": compid, "messages": {name: e.document() for name, e in messages.items()}}


def _id(part: str) -> int:
    if not (part.isascii() and part.isdigit()):
        raise KeyError(part)
    return int(part)


def _leaf(value: object, rest: list[str]) -> object:
    if rest:
        raise KeyError(rest[0])
    return value


def _pointer(value: object, parts: list[str]) -> object:
    """JSON pointer (RFC 6901) steps below an entry: object keys and list indexes."""
    for part in parts:
        part = part.replace("~1", "/").replace("~0", "~")
        if isinstance(value, dict):
            value = value[part]
        elif isinstance(value, list):
            if not (part.isascii() and part.isdigit()) or int(part) >= len(value):
                raise KeyError(part)
            value = value[int(part)]
        else:
            raise KeyError(part)
    return value
