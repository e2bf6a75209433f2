"""Authority in the configuration (SPEC.md "Authority"): named signing keys and HTTP tokens with a
role, a role per channel for its unsigned peers, and the role of a tokenless HTTP request.

    signing:
      keys:
        - {name: alice-qgc, key_file: keys/alice.key, role: operator}   # 64 hex characters
        - {name: lte-viewer, passphrase_file: keys/viewer.txt, role: observer}  # key = SHA-256(passphrase)
    channels:
      - {name: lan, type: udp-server, address: 0.0.0.0:14551, role: operator}
    http:
      tokens:
        - {name: dashboard, token_file: tokens/dash.txt, role: observer}
      anonymous_role: null   # null: operator, or observer when signing.require is true

A key or token file is named here and read at start (`read_key`, http.read_token; preflight
checks them first), its path taken as given, as http.token_file's. Names are unique per list,
printable ASCII without spaces (they go into the audit lines). On an mqtt channel `role` is
the MQTT role (vehicle | ground, config/mqtt.py); its peers have the default role.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from gcsd.config.reader import Field, Reader, Section
from gcsd.routing.authority import ROLE_NAMES, passphrase_key

KEY_ENTRY_KEYS = ("name", "key_file", "passphrase_file", "role")
TOKEN_ENTRY_KEYS = ("name", "token_file", "role")
DEFAULT_CHANNEL_ROLE = "admin"  # today's behaviour: whoever a channel admits may do everything
MAX_NAMED = 256
_NAME = re.compile(r"[A-Za-z0-9_.@-]{1,64}", re.ASCII)
_HEX_KEY = re.compile(r"[0-9a-fA-F]{64}", re.ASCII)


@dataclass(frozen=True)
class NamedKey:
    name: str
    role: str
    key_file: str | None = None  # 64 hex characters on the first line
    passphrase_file: str | None = None  # the first line is the passphrase


@dataclass(frozen=True)
class NamedToken:
    name: str
    role: str
    token_file: str


def _role(r: Reader, f: Field, default: str) -> str:
    return r.choice(f, default, ROLE_NAMES)


def _name(r: Reader, f: Field, seen: set[str], what: str) -> str:
    name = r.text(f, "")
    if name and not _NAME.fullmatch(name):
        r.problem(f, f"a {what} name is 1 to 64 of A-Z a-z 0-9 _ . @ -")
    elif name in seen:
        r.problem(f, f"duplicate {what} name {name!r}")
    seen.add(name)
    return name


def read_signing_keys(r: Reader, f: Field) -> tuple[NamedKey, ...]:
    items = r.sequence(f)
    if len(items) > MAX_NAMED:
        r.problem(f, f"at most {MAX_NAMED} keys, got {len(items)}")
    keys, seen = [], set()
    for item in items:
        s: Section = r.section(item, KEY_ENTRY_KEYS)
        if "name" not in s:
            r.problem(s["name"], "required for every key")
        name = _name(r, s["name"], seen, "key")
        key_file = r.path(s["key_file"], None, nullable=True)
        passphrase_file = r.path(s["passphrase_file"], None, nullable=True)
        if (key_file is None) == (passphrase_file is None):
            r.problem(s["key_file"] if "key_file" in s else s["name"],
                      "exactly one of key_file and passphrase_file")
        if "role" not in s:
            r.problem(s["role"], "required for every key (observer, operator or admin)")
        role = _role(r, s["role"], "observer")
        if name:
            keys.append(NamedKey(name=name, role=role, key_file=key_file, passphrase_file=passphrase_file))
    return tuple(keys)


def read_tokens(r: Reader, f: Field) -> tuple[NamedToken, ...]:
    tokens, seen = [], set()
    for item in r.sequence(f):
        s = r.section(item, TOKEN_ENTRY_KEYS)
        for key in ("name", "token_file", "role"):
            if key not in s:
                r.problem(s[key], "required for every token")
        name = _name(r, s["name"], seen, "token")
        token_file = r.path(s["token_file"], None)
        role = _role(r, s["role"], "observer")
        if name and token_file:
            tokens.append(NamedToken(name=name, role=role, token_file=token_file))
    return tuple(tokens)


def read_anonymous_role(r: Reader, f: Field, signing_require: bool) -> str:
    """http.anonymous_role: null is operator, or observer when signing.require is true."""
    default = "observer" if signing_require else "operator"
    if f.node is None or r.text(f, None, nullable=True) is None:
        return default
    return _role(r, f, default)


def read_channel_role(r: Reader, c: Section, channel_type: str) -> str:
    """A channel's `role` (not on mqtt channels, where `role` is the MQTT role)."""
    if channel_type == "mqtt":
        return DEFAULT_CHANNEL_ROLE
    return _role(r, c["role"], DEFAULT_CHANNEL_ROLE)


def key_from_text(text: str) -> bytes:
    """A key file's first line: 64 hex characters. Raises ValueError (never echoing the key)."""
    line = text.splitlines()[0].strip() if text.strip() else ""
    if not _HEX_KEY.fullmatch(line):
        raise ValueError(f"expected 64 hex characters on the first line, got {len(line)} characters")
    return bytes.fromhex(line)


def read_key(named: NamedKey, resolve) -> bytes:
    """The 32-byte key of a configured entry; `resolve(path)` turns a configured path into a
    file path (state_dir). Raises OSError or ValueError."""
    if named.key_file is not None:
        with open(resolve(named.key_file), encoding="utf-8") as file:
            return key_from_text(file.read())
    with open(resolve(named.passphrase_file), encoding="utf-8") as file:
        passphrase = file.readline().rstrip("\r\n")
    if not passphrase:
        raise ValueError("the first line (the passphrase) is empty")
    return passphrase_key(passphrase)
