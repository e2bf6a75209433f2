"""`GET /metrics` on the real daemon (SPEC.md "Web tools and monitoring"): Prometheus' text format
parsed by prometheus_client's own parser, checked by `promtool check metrics`, and scraped by a
real Prometheus server (Debian's `prometheus`; that test skips only when the binary is absent)
whose query API returns a packet counter that grows and a drop counter equal to `gcsd status`'s.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import urllib.parse

import pytest
from prometheus_client.parser import text_string_to_metric_families

from .helpers import VEHICLE, free_listener, is_type, udp_channel, udp_url, v2_frame, wait_for
from .http_client import call, poll

PROMETHEUS = shutil.which("prometheus") or ("/usr/bin/prometheus" if shutil.which("/usr/bin/prometheus") else None)
PROMTOOL = shutil.which("promtool")


def scrape(url: str) -> tuple[str, dict]:
    status, headers, _, text = call(f"{url}/metrics")
    assert status == 200, text
    assert headers["Content-Type"].startswith("text/plain; version=0.0.4")
    return text, samples(text)


def samples(text: str) -> dict:
    """{(name, frozenset(labels)): value} of every sample of the exposition."""
    out = {}
    for family in text_string_to_metric_families(text):
        for s in family.samples:
            out[(s.name, frozenset(s.labels.items()))] = s.value
    return out


def value(found: dict, name: str, **labels) -> float | None:
    return found.get((name, frozenset(labels.items())))


@pytest.fixture
def station(daemon, client):
    d = daemon({"channels": [udp_channel("gcs")]})
    gcs = client(udp_url(d.port("gcs")))
    gcs.heartbeat()
    assert wait_for(gcs, is_type("HEARTBEAT", VEHICLE)), "the ground station hears the vehicle"
    for seq in range(3):  # three frames with a bad CRC: the crc drop counter is not zero
        gcs.write(v2_frame(0, bytes(9), seq=seq))
    assert poll(lambda: d.stats("gcs")["crc_errors"] >= 3), "the bad frames are counted"
    return d, gcs


def test_metrics_parse_and_agree_with_status(station):
    d, gcs = station
    url = d.http_url()
    text, first = scrape(url)
    out = value(first, "gcsd_channel_packets_total", channel="gcs", direction="out")
    assert out and out > 0, "the vehicle's telemetry went out on gcs"
    # the counter grows while telemetry flows
    assert poll(lambda: value(scrape(url)[1], "gcsd_channel_packets_total", channel="gcs", direction="out") > out)
    status = d.status()
    gcs_status = next(ch for ch in status["channels"] if ch["name"] == "gcs")
    _, now = scrape(url)
    assert value(now, "gcsd_channel_dropped_total", channel="gcs", reason="crc") == gcs_status["crc_errors"] >= 3
    assert value(now, "gcsd_channel_peers", channel="gcs") == 1
    assert value(now, "gcsd_vehicle_armed", sysid="1") == 0
    assert value(now, "gcsd_vehicle_mode", sysid="1", mode=status["vehicles"][0]["mode"]) == 1
    assert value(now, "gcsd_routes") == len(status["routes"]) >= 1  # the ground station's route
    assert value(now, "gcsd_logs_captured_blocks_total") == 0
    assert value(now, "process_resident_memory_bytes") > 1e6
    assert value(now, "process_cpu_seconds_total") > 0
    assert value(now, "gcsd_loop_lag_seconds_count") is not None
    assert value(now, "gcsd_channel_bytes_total", channel="gcs", direction="in") >= gcs_status["bytes_in"] > 0
    # no label names a peer: every label value is from a bounded set (no address, no port)
    peer = f"{gcs.conn.port.getsockname()[1]}"
    assert peer not in {v for (_, labels) in now for (_, v) in labels}
    assert not any(k == "peer" or k == "address" for (_, labels) in now for (k, _) in labels)
    if PROMTOOL:
        checked = subprocess.run([PROMTOOL, "check", "metrics"], input=text.encode(), capture_output=True, check=False,
                                 timeout=10)
        assert checked.returncode == 0, checked.stdout + checked.stderr


def test_metrics_off_is_404_and_token_rules_apply(daemon, tmp_path):
    d = daemon({"channels": [udp_channel("gcs")], "metrics": False})
    assert call(f"{d.http_url()}/metrics")[0] == 404
    assert call(f"{d.http_url()}/v1/status")[0] == 200  # positive control: the API itself answers
    token = tmp_path / "token"
    token.write_text("s3cret\n")
    d2 = daemon({"channels": [udp_channel("gcs")], "http": {"address": "127.0.0.1:0", "token_file": str(token)}})
    assert call(f"{d2.http_url()}/metrics")[0] == 401
    status, _, _, text = call(f"{d2.http_url()}/metrics", headers={"Authorization": "Bearer s3cret"})
    assert status == 200 and "gcsd_channel_packets_total" in text


def test_prometheus_client_is_imported_only_at_the_first_scrape():
    code = ("import sys, gcsd.api.http.service, gcsd.api.http.routes, gcsd.daemon.compose; "
            "print('prometheus_client' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=30, check=False)
    assert out.stdout.strip() == "False", out.stderr
    code2 = "import sys, gcsd.api.http.metrics as m; m.Metrics(lambda: {}); print('prometheus_client' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code2], capture_output=True, text=True, check=False,
                          timeout=30).stdout.strip() == "True", "positive control: building Metrics imports it"


@pytest.mark.skipif(PROMETHEUS is None, reason="Debian's prometheus is not installed")
def test_real_prometheus_scrapes_gcsd(station, tmp_path):
    d, _ = station
    target = d.http_url().split("//", 1)[1]
    listener = free_listener()
    port = listener.getsockname()[1]
    listener.close()
    (tmp_path / "prometheus.yml").write_text(
        "global: {scrape_interval: 1s, scrape_timeout: 1s}\n"
        f"scrape_configs:\n  - job_name: gcsd\n    static_configs: [{{targets: ['{target}']}}]\n")
    proc = subprocess.Popen([PROMETHEUS, f"--config.file={tmp_path / 'prometheus.yml'}",
                             f"--storage.tsdb.path={tmp_path / 'data'}", f"--web.listen-address=127.0.0.1:{port}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        def query(expr: str):
            q = urllib.parse.urlencode({"query": expr})
            try:
                status, _, body, _ = call(f"http://127.0.0.1:{port}/api/v1/query?{q}", timeout=2)
            except OSError:  # not listening yet
                return None
            if status != 200 or body.get("status") != "success" or not body["data"]["result"]:
                return None
            return float(body["data"]["result"][0]["value"][1])

        packets = 'gcsd_channel_packets_total{channel="gcs",direction="out"}'
        first = poll(lambda: query(packets), timeout=15)
        assert first, "Prometheus scraped gcsd's packet counter"
        assert poll(lambda: (query(packets) or 0) > first, timeout=10), "the counter grows between scrapes"
        crc = next(ch for ch in d.status()["channels"] if ch["name"] == "gcs")["crc_errors"]
        assert poll(lambda: query('gcsd_channel_dropped_total{channel="gcs",reason="crc"}') == crc, timeout=5)
        assert query('up{job="gcsd"}') == 1
    finally:
        proc.terminate()
        try:
            proc.wait(5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
