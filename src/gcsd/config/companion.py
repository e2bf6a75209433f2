"""The companion-routing keys of a channel and the `routing` section (SPEC.md "Companion routing"),
read by config.py's reader.

    - name: radio
      type: serial
      baud: [921600, 115200, 57600]   # a list is cycled until a good frame arrives
      group: fc                       # channels of one group are redundant links to the same systems
      filter:                         # in: after the signature check, before routing and local handling
        in:  {block_msgids: [PARAM_VALUE]}
        out: {allow_src_sys: [1, 255]}   # out: everything written to the channel, forwarded or our own
      rate_limits: {ATTITUDE: 10}     # Hz per message id and source, on this channel's output
      request_streams: 4              # Hz: REQUEST_DATA_STREAM to each autopilot learned here
      options: [sign_forwarded]       # serial, or a loopback address only
    routing:
      dedup_ms: 0                     # > 0: the same frame bytes again within this window are dropped

Message ids are names of the ardupilotmega dialect (an unknown name is a problem naming the
line, with the closest name suggested) or numbers 0..16777215. Source systems and components
are 0..255. Both an allow and a block list may be given for the same field: a frame passes when
the allow list names it (or there is none) and the block list does not.
`sign_forwarded` is refused on a channel whose address is not a loopback one (127.0.0.0/8, ::1,
localhost): a signing gateway open to a LAN would hand signatures to strangers (MAVProxy#1683).
"""

from __future__ import annotations

import difflib
import ipaddress
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from yaml.nodes import MappingNode, ScalarNode, SequenceNode

FILTER_KEYS = ("allow_msgids", "block_msgids", "allow_src_sys", "block_src_sys", "allow_src_comp",
               "block_src_comp")
COMPANION_KEYS = ("group", "filter", "rate_limits", "request_streams")
ROUTING_KEYS = ("dedup_ms",)
MAX_MSGID = 0xFFFFFF  # MAVLink2 message ids are 24 bits
MAX_RATE_LIMIT_HZ = 1000.0
MAX_REQUEST_STREAMS_HZ = 50
MAX_DEDUP_MS = 10_000
MAX_BAUDS = 8
LOOPBACK_NAMES = ("localhost", "localhost.localdomain", "ip6-localhost")


@dataclass(frozen=True)
class FilterRules:
    """One direction's lists; None: no allow list (everything not blocked passes)."""

    allow_msgids: frozenset[int] | None = None
    block_msgids: frozenset[int] = frozenset()
    allow_src_sys: frozenset[int] | None = None
    block_src_sys: frozenset[int] = frozenset()
    allow_src_comp: frozenset[int] | None = None
    block_src_comp: frozenset[int] = frozenset()

    @property
    def empty(self) -> bool:
        return self == FilterRules()


@dataclass(frozen=True)
class ChannelFilter:
    inbound: FilterRules = FilterRules()
    outbound: FilterRules = FilterRules()


@dataclass(frozen=True)
class RoutingConfig:
    dedup_ms: int = 0


@dataclass(frozen=True)
class CompanionKeys:
    """What a channel section's companion keys give ChannelConfig."""

    group: str | None = None
    filter: ChannelFilter = ChannelFilter()
    rate_limits: Mapping[int, float] = field(default_factory=lambda: MappingProxyType({}))
    request_streams: int = 0


def message_ids() -> dict[str, int]:
    """The ardupilotmega dialect's message names -> ids."""
    from pymavlink.dialects.v20 import ardupilotmega as M

    return {name.removeprefix("MAVLINK_MSG_ID_"): value for name, value in vars(M).items()
            if name.startswith("MAVLINK_MSG_ID_") and isinstance(value, int)}


def message_id(value, names: dict[str, int]) -> tuple[int | None, str]:
    """A message name or number -> (id, "") or (None, why not)."""
    if type(value) is int:
        return (value, "") if 0 <= value <= MAX_MSGID else (None, f"a message id must be 0..{MAX_MSGID}, got {value}")
    if not isinstance(value, str) or not value:
        return None, f"expected a message name or id, got {value!r}"
    msgid = names.get(value.upper())
    if msgid is not None:
        return msgid, ""
    close = difflib.get_close_matches(value.upper(), list(names), n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    return None, f"unknown message {value!r} in the ardupilotmega dialect{hint}"


def is_loopback_host(host: str) -> bool:
    if host.lower() in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def read_bauds(r, f) -> tuple[int, ...]:
    """`baud: 57600` or `baud: [921600, 57600]` -> the bauds to try, in order."""
    if isinstance(f.node, SequenceNode):
        items = r.sequence(f)
        if not 1 <= len(items) <= MAX_BAUDS:
            r.problem(f, f"expected 1 to {MAX_BAUDS} baud rates, got {len(items)}")
        bauds = tuple(b for b in (r.integer(i, None, 1) for i in items) if b is not None)
        return bauds or (115200,)
    return (r.integer(f, 115200, 1),)


def read_companion(r, c, channel_type: str, address: tuple[str, int] | None, options: frozenset[str]) -> CompanionKeys:
    """The companion keys of one channel section (`c`), and the sign_forwarded check."""
    names: dict[str, int] = {}
    if "filter" in c or "rate_limits" in c:
        names = message_ids()
    group = r.text(c["group"], None, nullable=True)
    filt = ChannelFilter()
    if "filter" in c:
        directions = r.section(c["filter"], ("in", "out"))
        filt = ChannelFilter(_rules(r, directions["in"], names), _rules(r, directions["out"], names))
    request_hz = r.integer(c["request_streams"], 0, 0, MAX_REQUEST_STREAMS_HZ)
    if "sign_forwarded" in options:
        loopback = channel_type == "serial" or (address is not None and is_loopback_host(address[0]))
        if not loopback:
            r.problem(c["options"], "sign_forwarded is allowed only on serial channels and on channels bound "
                                    "to or pointed at a loopback address (127.0.0.1, ::1, localhost): "
                                    "anyone who can reach the channel could have frames signed")
    return CompanionKeys(group=group, filter=filt, rate_limits=_rate_limits(r, c["rate_limits"], names),
                         request_streams=request_hz)


def read_routing(r, f) -> RoutingConfig:
    s = r.section(f, ROUTING_KEYS)
    return RoutingConfig(dedup_ms=r.integer(s["dedup_ms"], 0, 0, MAX_DEDUP_MS))


def _rules(r, f, names: dict[str, int]) -> FilterRules:
    s = r.section(f, FILTER_KEYS)
    lists = {}
    for key in FILTER_KEYS:
        if key not in s:
            continue
        if key.endswith("msgids"):
            lists[key] = frozenset(_msgids(r, s[key], names))
        else:
            lists[key] = frozenset(v for v in (r.integer(i, None, 0, 255) for i in r.sequence(s[key]))
                                   if v is not None)
    return FilterRules(**lists)


def _msgids(r, f, names: dict[str, int]) -> list[int]:
    out = []
    for item in r.sequence(f):
        msgid, why = message_id(r.scalar(item.node) if isinstance(item.node, ScalarNode) else None, names)
        if msgid is None:
            r.problem(item, why)
        else:
            out.append(msgid)
    return out


def _rate_limits(r, f, names: dict[str, int]) -> Mapping[int, float]:
    if f.node is None or (isinstance(f.node, ScalarNode) and f.node.tag.endswith(":null")):
        return MappingProxyType({})
    if not isinstance(f.node, MappingNode):
        return r.reject(f, "a mapping of message name or id to Hz", MappingProxyType({}))
    out: dict[int, float] = {}
    for key_node, value_node in f.node.value:
        key = r.scalar(key_node)
        path = f"{f.path}.{key_node.value if isinstance(key_node, ScalarNode) else '?'}"
        key_field = type(f)(key_node, path)
        r.lines.setdefault(path, key_node.start_mark.line + 1)
        msgid, why = message_id(key, names)
        if msgid is None:
            r.problem(key_field, why)
            continue
        if msgid in out:
            r.problem(key_field, "duplicate message")
            continue
        out[msgid] = r.number(type(f)(value_node, path), 1.0, 0, MAX_RATE_LIMIT_HZ, low_open=True)
    return MappingProxyType(out)
