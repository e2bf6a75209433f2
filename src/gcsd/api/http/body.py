"""What a client sends the HTTP API, read without trusting it: JSON bounded in size and depth
before it is parsed (Python's parser recurses: RecursionError near 1 000 levels), no NaN or
Infinity constants, and ids from paths and queries in ASCII digits only. Every refusal is a
RequestFailed with its 4xx status, never a daemon error (gcsd.api.http.routes)."""

from __future__ import annotations

import json
import re
from itertools import accumulate

MAX_BODY_BYTES = 1 << 20
MAX_JSON_DEPTH = 64  # a .plan nests 8 deep


class RequestFailed(Exception):
    """A handler's answer other than 2xx: status and the error text."""

    def __init__(self, status: int, text: str) -> None:
        super().__init__(text)
        self.status = status


def _reject_constant(name: str) -> None:
    raise ValueError(f"{name} is not JSON")


_STRING = re.compile(rb'"(?:[^"\\]++|\\.)*+"', re.DOTALL)
_NOT_BRACKETS = bytes(b for b in range(256) if b not in b"[]{}")
_STEP = [0] * 256
_STEP[ord("[")] = _STEP[ord("{")] = 1
_STEP[ord("]")] = _STEP[ord("}")] = -1


def json_depth(data: bytes) -> int:
    """How deep the arrays and objects of a JSON text nest, without parsing it (strings skipped)."""
    brackets = _STRING.sub(b"", data).translate(None, _NOT_BRACKETS)
    return max(accumulate(_STEP[b] for b in brackets), default=0)


def parse_json(data: bytes | str) -> object:
    """A client's JSON text, bounded before parsing: RequestFailed(400) for malformed or too deep."""
    if isinstance(data, str):
        data = data.encode("utf-8", "surrogatepass")
    if len(data) > MAX_BODY_BYTES:
        raise RequestFailed(413, f"body over {MAX_BODY_BYTES} bytes")
    if json_depth(data) > MAX_JSON_DEPTH:
        raise RequestFailed(400, f"malformed JSON: nested deeper than {MAX_JSON_DEPTH}")
    try:
        return json.loads(data, parse_constant=_reject_constant)
    except (ValueError, UnicodeDecodeError, RecursionError) as exc:
        raise RequestFailed(400, f"malformed JSON: {exc}") from None


def ascii_id(text: str) -> int | None:
    """A decimal id from a path or a query (ASCII digits only: "²" passes str.isdigit())."""
    return int(text) if text.isascii() and text.isdigit() and len(text) <= 10 else None
