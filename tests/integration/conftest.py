"""Fixtures for integration tests: pymavlink clients that are always closed at teardown."""

from __future__ import annotations

import pytest

from .helpers import Client


@pytest.fixture
def client():
    """`client(url, sysid, compid, version=2)` -> a Client, closed at teardown."""
    made: list[Client] = []

    def make(url: str, sysid: int = 255, compid: int = 190, version: int = 2) -> Client:
        c = Client(url, sysid, compid, version)
        made.append(c)
        return c

    yield make
    for c in made:
        c.close()
