"""Broadcast discovery's lock (gcsd.links.discovery) with a float clock, and its configuration key."""

from __future__ import annotations

import pytest

from gcsd.config import ConfigError, parse_config
from gcsd.links.discovery import STATION_SILENT_S, BroadcastLock

BCAST = ("255.255.255.255", 14550)
QGC = ("192.168.1.20", 14550)
OTHER = ("192.168.1.30", 14550)


def test_it_broadcasts_and_reads_anyone_until_a_station_answers():
    lock = BroadcastLock(BCAST)
    assert lock.destination(0.0) == (BCAST, False)
    assert lock.accepts(QGC) and lock.accepts(OTHER)


def test_the_first_good_frame_locks_onto_its_sender_only():
    lock = BroadcastLock(BCAST)
    assert lock.heard(QGC, 1.0) is True
    assert lock.destination(1.5) == (QGC, False)
    assert lock.accepts(QGC) and not lock.accepts(OTHER)
    assert lock.heard(QGC, 2.0) is False  # already locked


def test_a_station_silent_for_30_s_releases_the_lock():
    lock = BroadcastLock(BCAST)
    lock.heard(QGC, 10.0)
    assert lock.destination(10.0 + STATION_SILENT_S) == (QGC, False)
    assert lock.destination(10.0 + STATION_SILENT_S + 0.01) == (BCAST, True)
    assert lock.destination(50.0) == (BCAST, False)
    assert lock.accepts(OTHER)
    assert lock.heard(OTHER, 51.0) is True and lock.destination(51.0) == (OTHER, False)


def test_broadcast_is_a_udp_client_key():
    config = parse_config("channels:\n  - {name: lan, type: udp-client, address: '255.255.255.255:14550',"
                          " broadcast: true}\n", "c.yaml")
    assert config.channels[0].broadcast is True
    assert parse_config("channels:\n  - {name: a, type: udp-client, address: '1.2.3.4:5'}\n").channels[0].broadcast \
        is False


@pytest.mark.parametrize("kind", ["udp-server", "tcp-client"])
def test_broadcast_on_another_channel_type_is_refused_with_its_line(kind):
    with pytest.raises(ConfigError) as err:
        parse_config(f"channels:\n  - name: a\n    type: {kind}\n    address: 127.0.0.1:5\n    broadcast: true\n",
                     "c.yaml")
    assert err.value.problems == ["c.yaml:5: channels[0].broadcast: only used by udp-client channels"]


def test_broadcast_must_be_a_boolean():
    with pytest.raises(ConfigError) as err:
        parse_config("channels:\n  - {name: a, type: udp-client, address: '1.2.3.4:5', broadcast: yes please}\n",
                     "c.yaml")
    assert err.value.problems == ["c.yaml:2: channels[0].broadcast: expected true or false, got 'yes please'"]
