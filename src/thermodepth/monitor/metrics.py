"""The monitor's figures in Prometheus' text format (``GET /metrics``): per rig its freshness,
rate, counters, sensor temperature, pipeline time and active alarms; events by state; the
event store's size, free disk and alarm latencies; each worker of the monitor's state and
restarts. Read when scraped, from
:meth:`~.service.Monitor.status`."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any


def collector(current: Callable[[], dict[str, Any]]) -> Any:
    """A prometheus_client collector of the figures ``current()`` gives, read when scraped."""
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

    class Collector:
        def collect(self) -> Iterator[Any]:
            status = current()
            rigs = status["rigs"]

            def per_rig(kind: type, name: str, doc: str, key: str) -> Any:
                family = kind(name, doc, labels=["rig"])
                for r in rigs:
                    value = r[key]
                    family.add_metric([r["name"]], float("nan") if value is None else value)
                return family

            yield per_rig(GaugeMetricFamily, "thermodepth_rig_up", "1 while fresh", "up")
            yield per_rig(GaugeMetricFamily, "thermodepth_rig_fps", "frames/s, 5 s", "fps")
            yield per_rig(
                GaugeMetricFamily,
                "thermodepth_rig_last_frame_age_seconds",
                "seconds since the rig's last frame",
                "last_frame_age_s",
            )
            yield per_rig(CounterMetricFamily, "thermodepth_rig_frames", "frames fused", "frames")
            yield per_rig(
                CounterMetricFamily, "thermodepth_rig_reconnects", "reopenings", "reconnects"
            )
            yield per_rig(CounterMetricFamily, "thermodepth_rig_stalls", "stalls", "stalls")
            yield per_rig(
                CounterMetricFamily,
                "thermodepth_rig_seconds_without_data",
                "seconds with no fresh data",
                "seconds_without_data",
            )
            yield per_rig(
                CounterMetricFamily, "thermodepth_rig_dropped", "paced pairs dropped", "dropped"
            )
            yield per_rig(GaugeMetricFamily, "thermodepth_rig_ffc", "shutter closing", "ffc")
            yield per_rig(
                GaugeMetricFamily, "thermodepth_rig_vox_celsius", "sensor temp", "vox_temp_c"
            )
            ms = GaugeMetricFamily(
                "thermodepth_rig_pipeline_seconds",
                "a pair's time through the pipeline, over the last 200",
                labels=["rig", "quantile"],
            )
            alarms = GaugeMetricFamily(
                "thermodepth_rig_alarms_active", "alarms raised now", labels=["rig", "level"]
            )
            for r in rigs:
                for q, key in (("0.5", "median"), ("0.99", "p99")):
                    value = r["pipeline_ms"][key]
                    ms.add_metric([r["name"], q], float("nan") if value is None else value / 1e3)
                for level in ("warning", "alarm"):
                    n = sum(a["level"] == level for a in r["active_alarms"])
                    alarms.add_metric([r["name"], level], n)
            yield ms
            yield alarms
            events = CounterMetricFamily(
                "thermodepth_events", "events since start", labels=["rig", "state"]
            )
            for rig, counts in status["event_counts"].items():
                for state, n in sorted(counts.items()):
                    events.add_metric([rig, state], n)
            yield events
            store = status["storage"]
            yield GaugeMetricFamily(
                "thermodepth_event_store_bytes",
                "event store size",
                value=store["event_store_bytes"],
            )
            yield GaugeMetricFamily(
                "thermodepth_storage_free_bytes", "free disk", value=store["free_bytes"]
            )
            latency = GaugeMetricFamily(
                "thermodepth_alarm_latency_seconds",
                "from a frame's capture to its event's row, and to the broker's acknowledgement",
                labels=["to", "quantile"],
            )
            for to, figures in status["latency_s"].items():
                for q, key in (("0.5", "median"), ("0.99", "p99")):
                    value = figures[key]
                    latency.add_metric([to, q], float("nan") if value is None else value)
            yield latency
            up = GaugeMetricFamily(
                "thermodepth_worker_up", "1 while the worker is well", labels=["worker"]
            )
            restarts = CounterMetricFamily(
                "thermodepth_worker_restarts", "restarts after a failure", labels=["worker"]
            )
            for w in status.get("workers", []):
                up.add_metric([w["name"]], int(w["healthy"] and w["state"] == "running"))
                restarts.add_metric([w["name"]], w["restarts"])
            yield up
            yield restarts

    return Collector()
