"""The `http` section: where the HTTP and WebSocket API listens and the token it wants.

    http:
      address: 127.0.0.1:8088   # null turns it off; a non-loopback address requires token_file
      token_file: null          # a file whose first line is the bearer token every request must carry

An address other than a loopback one (127.0.0.0/8, ::1, localhost) without `token_file` is a
configuration error: the API can arm a vehicle. The token file is read at start (preflight,
`read_token`); a file that cannot be read or whose first line is empty stops the start with a
`FILE:LINE: http.token_file:` line, as every other configuration problem.
"""

from __future__ import annotations

from dataclasses import dataclass

from gcsd.config.authority import read_anonymous_role, read_tokens
from gcsd.config.companion import is_loopback_host
from gcsd.config.reader import Field, Reader, is_null

HTTP_KEYS = ("address", "token_file", "tokens", "anonymous_role")
DEFAULT_HTTP_ADDRESS = ("127.0.0.1", 8088)


@dataclass(frozen=True)
class HttpConfig:
    address: tuple[str, int] | None = DEFAULT_HTTP_ADDRESS  # None: no HTTP API
    token_file: str | None = None
    tokens: tuple = ()  # NamedToken entries (config/authority.py), besides token_file (admin)
    anonymous_role: str = "operator"  # a request without a token, on loopback (config/authority.py)


def read_http(r: Reader, f: Field, read_address, signing_require: bool = False) -> HttpConfig:
    section = r.section(f, HTTP_KEYS)
    address_field = section["address"]
    if address_field.node is not None and is_null(address_field.node):
        address = None
    elif address_field.node is None:
        address = DEFAULT_HTTP_ADDRESS
    else:
        address = read_address(r, address_field)
    token_file = r.path(section["token_file"], None, nullable=True)
    if address is not None and token_file is None and not is_loopback_host(address[0]):
        r.problem(address_field, f"{address[0]} is not a loopback address: set http.token_file too (the API "
                                 "can arm the vehicle)")
    return HttpConfig(address=address, token_file=token_file, tokens=read_tokens(r, section["tokens"]),
                      anonymous_role=read_anonymous_role(r, section["anonymous_role"], signing_require))


def read_token(path: str) -> str:
    """The token: the file's first line, stripped. Raises OSError or ValueError (empty)."""
    with open(path, encoding="utf-8") as file:
        token = file.readline().strip()
    if not token:
        raise ValueError("the first line is empty")
    return token
