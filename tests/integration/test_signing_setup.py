"""SETUP_SIGNING's initial timestamp against the real daemon (issue 17, items 4 and 5): a ground
station with a wrong clock, or a hostile timestamp, must neither lock the signed stations out nor
mute the vehicle, before or after a restart, and a timestamp saved by an earlier run is repaired."""

from __future__ import annotations

from gcsd.wire.signing import UNITS_PER_S

from .helpers import Client, M, udp_channel, udp_url, wait_for
from .test_signing import KEY, arm_ack, now_units, sign

DAY_UNITS = 86400 * UNITS_PER_S


def two_channels(daemon, tmp_path):
    return daemon({
        "state_dir": str(tmp_path / "st"), "signing": {"require": True},
        "channels": [udp_channel("gcs"), udp_channel("open", options=["unsigned_ok"])],
    })


def setup_signing(d, client, timestamp: int) -> Client:
    trusted = client(udp_url(d.port("open")), 254, 190)
    mark = trusted.mark()
    trusted.send(M.MAVLink_setup_signing_message(1, 1, KEY, timestamp))
    assert wait_for(trusted, lambda r: r.type == "STATUSTEXT" and "Signing enabled" in r.msg.text, since=mark)
    return trusted


def signed_station(d, client, link_id: int) -> Client:
    station = client(udp_url(d.port("gcs")), 240, 190)
    sign(station, KEY, link_id=link_id)
    return station


def heartbeats(c: Client, seconds: float = 2.5) -> int:
    """HEARTBEATs from the vehicle in `seconds` (the client announces itself first)."""
    c.heartbeat()
    mark = c.mark()
    wait_for(c, lambda r: False, timeout=seconds)
    return len([r for r in c.since(mark, "HEARTBEAT") if r.src == (1, 1)])


def test_a_setup_a_day_ahead_locks_no_signed_station_out_not_even_after_a_restart(daemon, client, tmp_path):
    d = two_channels(daemon, tmp_path)
    setup_signing(d, client, now_units() + DAY_UNITS)
    assert arm_ack(signed_station(d, client, 1)) is not None, "a station with a correct clock is answered"
    d.stop()
    d2 = two_channels(daemon, tmp_path)
    assert arm_ack(signed_station(d2, client, 2)) is not None, "and still after a restart"
    assert d2.stats("gcs").get("signature_rejects_stale", 0) == 0


def test_a_later_setup_repairs_a_timestamp_ahead_within_the_limit(daemon, client, tmp_path):
    d = two_channels(daemon, tmp_path)
    setup_signing(d, client, now_units() + 200 * UNITS_PER_S)  # a clock 200 s ahead: taken
    assert arm_ack(signed_station(d, client, 1), timeout=1.0) is None
    assert d.stats("gcs")["signature_rejects_stale"] >= 1, "the control: the station was stale"
    setup_signing(d, client, now_units())  # ArduPilot assigns: the second setup repairs it
    assert arm_ack(signed_station(d, client, 2)) is not None


def test_a_setup_with_the_largest_timestamp_never_mutes_the_vehicle(daemon, client, tmp_path):
    d = two_channels(daemon, tmp_path)
    trusted = setup_signing(d, client, 2**64 - 1)
    assert heartbeats(trusted) >= 2, "signed HEARTBEATs keep coming"
    assert arm_ack(signed_station(d, client, 1)) is not None
    assert d.status()["errors"] == {}, "no send failed"
    d.stop()
    d2 = two_channels(daemon, tmp_path)
    assert heartbeats(client(udp_url(d2.port("open")), 254, 190)) >= 2, "and after a restart"


def test_a_bad_timestamp_saved_by_an_earlier_run_is_repaired_at_start(daemon, client, tmp_path):
    for bad in (now_units() + DAY_UNITS, 2**64 - 1):
        st = tmp_path / f"st{bad}"
        st.mkdir()
        (st / "signing.key").write_text(f"key {KEY.hex()}\ntimestamp {bad}\nclean 1\n")
        d = daemon({
            "state_dir": str(st), "signing": {"require": True},
            "channels": [udp_channel("gcs"), udp_channel("open", options=["unsigned_ok"])],
        })
        assert arm_ack(signed_station(d, client, 1)) is not None
        assert heartbeats(client(udp_url(d.port("open")), 254, 190)) >= 2
        d.stop()
        saved = int(dict(line.split() for line in (st / "signing.key").read_text().splitlines())["timestamp"])
        assert saved < now_units() + 600 * UNITS_PER_S, "the repaired value is what is saved"
