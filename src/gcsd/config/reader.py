"""The configuration reader: PyYAML nodes in, values or problems out (config.py holds the schema).

A `Reader` walks composed nodes, not loaded values, so every value keeps its line. Each check
(`integer`, `number`, `boolean`, `text`, `path`, `choice`, `section`, `sequence`) returns the
value, or records a problem ``FILE:LINE: key.path: what is wrong`` and returns the key's default,
so one pass finds every problem. `section` reports unknown keys (with the closest known one) and
duplicate keys, and records the line of every key path it sees (`lines`, for Config.source).
Text values are read from their source text, so ``address: 1:30`` is not YAML 1.1's
sexagesimal 90.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass

import yaml
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

_NULL_TAG = "tag:yaml.org,2002:null"
_STR_TAG = "tag:yaml.org,2002:str"
_NOT_A_SCALAR = object()


@dataclass(frozen=True)
class Field:
    """A key's value node (None when the key is absent) and its key path, for messages."""

    node: Node | None
    path: str
    parent: Node | None = None  # the mapping, to give a line to problems about absent keys


class Section:
    """The known keys of one mapping; unknown and duplicate keys were reported when it was read."""

    def __init__(self, node: Node | None, path: str, nodes: dict[str, Node]) -> None:
        self.node, self.path, self.nodes = node, path, nodes

    def __getitem__(self, key: str) -> Field:
        return Field(self.nodes.get(key), f"{self.path}.{key}" if self.path else key, self.node)

    def __contains__(self, key: str) -> bool:  # present in the file
        return key in self.nodes


class Reader:
    def __init__(self, filename: str) -> None:
        self.filename = filename
        self.problems: list[tuple[int, str]] = []
        self.lines: dict[str, int] = {}  # key path -> line, for Config.source
        self._constructor = yaml.constructor.SafeConstructor()

    def problem(self, f: Field, message: str) -> None:
        node = f.node if f.node is not None else f.parent
        line = line_of(node) if node is not None else 1
        self.problems.append((line, f"{self.filename}:{line}: {f.path}: {message}"))

    def reject(self, f: Field, wanted: str, default):
        self.problem(f, f"expected {wanted}, got {describe(f.node)}")
        return default

    def section(self, f: Field, known: tuple[str, ...]) -> Section:
        if f.node is not None and not is_null(f.node) and not isinstance(f.node, MappingNode):
            self.reject(f, "a mapping", None)
        if not isinstance(f.node, MappingNode):
            return Section(f.node, f.path, {})
        nodes: dict[str, Node] = {}
        for key_node, value_node in f.node.value:
            key = key_node.value if isinstance(key_node, ScalarNode) else "?"
            key_field = Field(key_node, f"{f.path}.{key}" if f.path else key)
            self.lines.setdefault(key_field.path, line_of(key_node))
            if key not in known:
                self.problem(key_field, _unknown_key(key, known))
            elif key in nodes:
                self.problem(key_field, "duplicate key")
            else:
                nodes[key] = value_node
        return Section(f.node, f.path, nodes)

    def sequence(self, f: Field) -> list[Field]:
        if f.node is None or is_null(f.node):
            return []
        if not isinstance(f.node, SequenceNode):
            return self.reject(f, "a list", [])
        items = [Field(item, f"{f.path}[{i}]") for i, item in enumerate(f.node.value)]
        for item in items:
            self.lines.setdefault(item.path, line_of(item.node))
        return items

    def scalar(self, node: Node):
        if not isinstance(node, ScalarNode):
            return _NOT_A_SCALAR
        try:
            return self._constructor.construct_object(node)
        except (yaml.YAMLError, ValueError):
            return _NOT_A_SCALAR

    def checked(self, f: Field, default, wanted: str, is_good, *, nullable: bool = False):
        """The YAML value of a scalar if `is_good(value)`, else a problem and the default."""
        if f.node is None or (nullable and is_null(f.node)):
            return default
        value = self.scalar(f.node)
        if value is _NOT_A_SCALAR or not is_good(value):
            return self.reject(f, wanted + (" or null" if nullable else ""), default)
        return value

    def integer(self, f: Field, default, low: int, high: int | None = None, *, nullable: bool = False):
        wanted = f"an integer {low}..{high}" if high is not None else f"an integer >= {low}"
        return self.checked(f, default, wanted, lambda v: type(v) is int and low <= v
                            and (high is None or v <= high), nullable=nullable)

    def number(self, f: Field, default: float, low: float, high: float, *, low_open: bool = False) -> float:
        wanted = f"a number > {low} and <= {high}" if low_open else f"a number {low}..{high}"
        return float(self.checked(f, default, wanted, lambda v: type(v) in (int, float)
                                  and (low < v if low_open else low <= v) and v <= high))

    def boolean(self, f: Field, default: bool) -> bool:
        return self.checked(f, default, "true or false", lambda v: type(v) is bool)

    def text(self, f: Field, default, *, nullable: bool = False):
        """The source text of a scalar, whatever YAML would make of it; empty text is a problem."""
        if f.node is None or (nullable and is_null(f.node)):
            return default
        if not isinstance(f.node, ScalarNode) or is_null(f.node) or not f.node.value:
            return self.reject(f, "a non-empty string" + (" or null" if nullable else ""), default)
        return f.node.value

    def path(self, f: Field, default, *, nullable: bool = False):
        """A file or directory name: text without NUL bytes (no system call can take one)."""
        value = self.text(f, default, nullable=nullable)
        if isinstance(value, str) and "\0" in value:
            self.problem(f, "a path cannot contain a NUL byte")
            return default
        return value

    def choice(self, f: Field, default: str, choices: tuple[str, ...]) -> str:
        value = self.text(f, None)
        if value is None:
            return default
        if value not in choices:
            self.problem(f, f"expected {'|'.join(choices)}, got {value!r}{_suggestion(value, choices)}")
            return default
        return value


def _unknown_key(key: str, known: tuple[str, ...]) -> str:
    return "unknown key" + (_suggestion(key, known) or f" (known keys: {', '.join(known)})")


def _suggestion(word: str, known: tuple[str, ...]) -> str:
    close = difflib.get_close_matches(word, known, n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def is_null(node: Node) -> bool:
    return isinstance(node, ScalarNode) and node.tag == _NULL_TAG


def line_of(node: Node) -> int:
    return node.start_mark.line + 1


def describe(node: Node | None) -> str:
    """A value as a message shows it: 'text', 300, true, null, a list, a mapping."""
    if node is None or is_null(node):
        return "null"
    if not isinstance(node, ScalarNode):
        return "a mapping" if isinstance(node, MappingNode) else "a list"
    return repr(node.value) if node.tag == _STR_TAG else node.value
