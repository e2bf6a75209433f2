"""`GET /metrics`: the daemon in Prometheus' text format, written by the Prometheus project's own
Python client (prometheus_client), imported only when /metrics is first asked (the daemon stays
small for those who never scrape it).

Each scrape reads the status document (`gcsd status --json`, gcsd.api.status) and turns it into
metric families, so /metrics and `gcsd status` never disagree:

  gcsd_channel_packets_total{channel,direction}   accepted frames in, frames sent out
  gcsd_channel_bytes_total{channel,direction}
  gcsd_channel_dropped_total{channel,reason}      frames not passed on, by reason (DROP_REASONS)
  gcsd_channel_peers{channel}                     peers served now
  gcsd_routes                                     learned routes
  gcsd_vehicle_armed{sysid}, gcsd_vehicle_mode{sysid,mode} (1 for the current mode)
  gcsd_logs_captured_blocks_total, gcsd_logs_served_bytes_total
  gcsd_events_total{event}                        the status document's other counted events
  gcsd_errors_total{component}                    exceptions caught per component
  gcsd_loop_lag_seconds                           a histogram: how late a timer of the loop ran
  process_*                                       the client's standard process collector

Every label takes values from a bounded set: channel names come from the configuration, reasons,
events and components from the code, sysids from 1..255, modes from the vehicle type's table;
no peer address, no message name.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable

# the text format every Prometheus server reads (2.x included; the client's newest says 1.0.0,
# which Debian 12's Prometheus 2.42 does not know): generate_latest writes it
CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"
LAG_SAMPLE_S = 0.25  # how often the loop's lag is measured (a timer due in this much)
LAG_BUCKETS_S = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5)
# the status document's channel counter -> the reason label of gcsd_channel_dropped_total
DROP_REASONS = {
    "drops": "budget", "muted": "muted", "spoofed_dropped": "spoofed", "retained_dropped": "retained",
    "duplicates": "duplicate", "loop_dropped": "loop", "replies_dropped": "replies",
    "filtered_in": "filtered_in", "filtered_out": "filtered_out", "rate_limited": "rate_limited",
    "parse_errors": "parse_error", "crc_errors": "crc", "unknown_ids": "unknown_id",
    "signature_rejects": "signature",
}
_LOG_COUNTERS = {"logs_capture_blocks": ("gcsd_logs_captured_blocks",
                                         "DataFlash blocks captured from flight controllers"),
                 "logs_bytes_served": ("gcsd_logs_served_bytes", "log bytes served by LOG_REQUEST_DATA")}


class Metrics:
    """The registry of one HTTP API: `exposition()` is the body of a scrape (bytes, the content type)."""

    def __init__(self, status: Callable[[], dict]) -> None:
        from prometheus_client import CollectorRegistry, Histogram, ProcessCollector

        self.registry = CollectorRegistry(auto_describe=False)
        self.registry.register(_StatusCollector(status))
        ProcessCollector(registry=self.registry)
        self.lag = Histogram("gcsd_loop_lag_seconds", "how late a timer of the event loop ran",
                             buckets=LAG_BUCKETS_S, registry=self.registry)
        self._sampler: asyncio.Task | None = None

    def start(self) -> None:
        """The loop-lag sampler, on the running loop (from the first scrape on)."""
        if self._sampler is None or self._sampler.done():
            self._sampler = asyncio.get_running_loop().create_task(self._sample_lag())

    def stop(self) -> None:
        if self._sampler is not None:
            self._sampler.cancel()

    def exposition(self) -> tuple[bytes, str]:
        from prometheus_client import generate_latest

        return generate_latest(self.registry), CONTENT_TYPE

    async def _sample_lag(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            due = loop.time() + LAG_SAMPLE_S
            await asyncio.sleep(LAG_SAMPLE_S)
            self.lag.observe(max(0.0, loop.time() - due))


class _StatusCollector:
    def __init__(self, status: Callable[[], dict]) -> None:
        self._status = status

    def collect(self):
        from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

        doc = self._status()
        packets = CounterMetricFamily("gcsd_channel_packets", "MAVLink packets per channel",
                                      labels=("channel", "direction"))
        octets = CounterMetricFamily("gcsd_channel_bytes", "MAVLink bytes per channel",
                                     labels=("channel", "direction"))
        dropped = CounterMetricFamily("gcsd_channel_dropped", "frames not passed on, by reason",
                                      labels=("channel", "reason"))
        peers = GaugeMetricFamily("gcsd_channel_peers", "peers served now", labels=("channel",))
        for ch in doc["channels"]:
            name = ch["name"]
            for direction in ("in", "out"):
                packets.add_metric((name, direction), ch.get(f"packets_{direction}", 0))
                octets.add_metric((name, direction), ch.get(f"bytes_{direction}", 0))
            for key, reason in DROP_REASONS.items():
                dropped.add_metric((name, reason), ch.get(key, 0))
            peers.add_metric((name,), ch.get("peers", 0))
        yield from (packets, octets, dropped, peers)
        yield GaugeMetricFamily("gcsd_routes", "learned routes (system, component) -> channel",
                                value=len(doc["routes"]))
        armed = GaugeMetricFamily("gcsd_vehicle_armed", "1 while the vehicle is armed", labels=("sysid",))
        mode = GaugeMetricFamily("gcsd_vehicle_mode", "1 for the vehicle's current mode", labels=("sysid", "mode"))
        for v in doc["vehicles"]:
            armed.add_metric((str(v["sysid"]),), 1.0 if v["armed"] else 0.0)
            mode.add_metric((str(v["sysid"]), str(v["mode"])), 1.0)
        yield from (armed, mode)
        counters = dict(doc["counters"])
        for key, (metric, text) in _LOG_COUNTERS.items():
            yield CounterMetricFamily(metric, text, value=counters.pop(key, 0))
        events = CounterMetricFamily("gcsd_events", "counted events outside the channels", labels=("event",))
        for key, n in counters.items():
            events.add_metric((key,), n)
        yield events
        errors = CounterMetricFamily("gcsd_errors", "exceptions caught, per component", labels=("component",))
        for component, n in doc["errors"].items():
            errors.add_metric((component,), n)
        yield errors
        yield GaugeMetricFamily("gcsd_uptime_seconds", "since the daemon started", value=doc["uptime_s"])
