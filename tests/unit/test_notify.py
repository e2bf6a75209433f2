"""systemd's notify protocol (notify.py): the watchdog interval is half of WATCHDOG_USEC, as
sd_watchdog_enabled(3) advises, and only the process systemd meant pings; messages reach a real
datagram socket. (The integration test awaits the pings of a real daemon without timing them.)"""

from __future__ import annotations

import socket

import pytest

from gcsd.daemon.notify import Notifier


@pytest.mark.parametrize(("usec", "interval_s"), [("600000", 0.3), ("10000000", 5.0), ("1", 5e-7)])
def test_watchdog_pings_at_half_the_interval_systemd_gives(usec, interval_s):
    assert Notifier({"NOTIFY_SOCKET": "/run/n", "WATCHDOG_USEC": usec}).watchdog_interval_s == interval_s


@pytest.mark.parametrize("env", [
    {"NOTIFY_SOCKET": "/run/n"},  # no WatchdogSec
    {"NOTIFY_SOCKET": "/run/n", "WATCHDOG_USEC": "0"},
    {"NOTIFY_SOCKET": "/run/n", "WATCHDOG_USEC": "ten"},
    {"NOTIFY_SOCKET": "/run/n", "WATCHDOG_USEC": "600000", "WATCHDOG_PID": "1"},  # meant for another process
])
def test_no_watchdog_pings_unless_systemd_asks_this_process(env):
    assert Notifier(env).watchdog_interval_s is None


def test_outside_systemd_nothing_is_sent():
    n = Notifier({})
    assert not n.enabled and not n.ready() and not n.watchdog() and not n.stopping()


def test_ready_watchdog_and_stopping_reach_the_socket(tmp_path):
    path = tmp_path / "notify.sock"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        sock.bind(str(path))
        sock.settimeout(5.0)
        n = Notifier({"NOTIFY_SOCKET": str(path)})
        assert n.ready("1 of 1 channels open") and n.watchdog() and n.stopping()
        got = [sock.recv(4096).decode() for _ in range(3)]
    assert got == ["READY=1\nSTATUS=1 of 1 channels open", "WATCHDOG=1", "STOPPING=1"]
