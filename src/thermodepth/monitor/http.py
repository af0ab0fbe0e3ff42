"""The monitor's health and API over HTTP (Starlette on uvicorn, on a thread of its own).

==================================  ============================================================
route                               what
==================================  ============================================================
``GET /healthz``                    200 while every rig has fresh data, else 503 naming the
                                    rigs that have none (no token needed: for probes)
``GET /api/status``                 per rig: frames/s, age of the last frame, reconnects,
                                    stalls, seconds without data, FFC, VOx, pipeline ms, active
                                    alarms; the storage, the event store, the broker, latencies
``GET /api/events``                 events, newest first (``limit`` <= 1000, ``rig``,
                                    ``before`` an id, for the next page)
``POST /api/ack``                   acknowledge ``{"rig", "rule", "by"}``: 200 with its
                                    events, 404 no such rig or rule, 409 not raised
``GET /metrics``                    the same figures in Prometheus' text format
==================================  ============================================================

With ``http.token_file`` every route but ``/healthz`` wants ``Authorization: Bearer TOKEN``
(401 otherwise).
"""

from __future__ import annotations

import hmac
import socket
import threading
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any, Protocol

from ..errors import InputError
from .config import HttpConfig, read_token
from .supervisor import AckRefusedError

if TYPE_CHECKING:
    from starlette.applications import Starlette
    from starlette.requests import Request
    from starlette.responses import Response


class Monitor(Protocol):
    """What the routes ask of the monitor (:class:`~.service.Monitor` is one)."""

    def status(self) -> dict[str, Any]: ...

    def stale_rigs(self) -> list[str]: ...

    def events(
        self, limit: int = 100, rig: str | None = None, before_id: int | None = None
    ) -> list[dict[str, Any]]: ...

    def acknowledge(self, rig: str, rule: str, by: str) -> list[dict[str, Any]]: ...


INSTALL = "the monitor's HTTP server needs the monitor extra: pip install 'thermodepth[monitor]'"


def _collector(monitor: Monitor) -> Any:
    """A prometheus_client collector of the monitor's figures, read when scraped."""
    from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily

    class Collector:
        def collect(self) -> Iterator[Any]:
            status = monitor.status()
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

    return Collector()


def build_app(monitor: Monitor, token: str | None) -> Starlette:
    """The Starlette application of the routes (module docstring)."""
    from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, generate_latest
    from starlette.applications import Starlette
    from starlette.responses import JSONResponse, Response
    from starlette.routing import Route

    registry = CollectorRegistry()
    registry.register(_collector(monitor))

    def refused(request: Request) -> Response | None:
        if token is None:
            return None
        given = request.headers.get("authorization", "")
        if hmac.compare_digest(given.encode(), f"Bearer {token}".encode()):
            return None
        return JSONResponse({"error": "a bearer token is needed"}, 401)

    async def healthz(request: Request) -> Response:
        stale = monitor.stale_rigs()
        if stale:
            return JSONResponse({"status": "stale", "rigs": stale}, 503)
        return JSONResponse({"status": "ok"})

    async def status(request: Request) -> Response:
        return refused(request) or JSONResponse(monitor.status())

    async def events(request: Request) -> Response:
        if (no := refused(request)) is not None:
            return no
        q = request.query_params
        try:
            limit = min(int(q.get("limit", "100")), 1000)
            before = int(q["before"]) if "before" in q else None
            if limit < 1:
                raise ValueError
        except ValueError:
            return JSONResponse({"error": "limit and before are whole numbers, limit >= 1"}, 400)
        return JSONResponse(monitor.events(limit, q.get("rig"), before))

    async def ack(request: Request) -> Response:
        if (no := refused(request)) is not None:
            return no
        try:
            body = await request.json()
        except ValueError:
            body = None
        fields = ("rig", "rule", "by")
        if not isinstance(body, dict) or not all(isinstance(body.get(k), str) for k in fields):
            return JSONResponse({"error": 'expected {"rig": ..., "rule": ..., "by": ...}'}, 400)
        if not body["by"].strip():
            return JSONResponse({"error": "by: say who acknowledges"}, 400)
        try:
            return JSONResponse(monitor.acknowledge(body["rig"], body["rule"], body["by"]))
        except AckRefusedError as exc:
            return JSONResponse({"error": exc.message}, exc.status)

    async def metrics(request: Request) -> Response:
        return refused(request) or Response(
            generate_latest(registry), media_type=CONTENT_TYPE_LATEST
        )

    return Starlette(
        routes=[
            Route("/healthz", healthz),
            Route("/api/status", status),
            Route("/api/events", events),
            Route("/api/ack", ack, methods=["POST"]),
            Route("/metrics", metrics),
        ]
    )


class HttpServer:
    """The application served by uvicorn on a thread of its own; ``start`` binds the address
    first, so that one taken is one InputError line."""

    def __init__(self, monitor: Monitor, config: HttpConfig) -> None:
        try:
            import uvicorn

            app = build_app(
                monitor, None if config.token_file is None else read_token(config.token_file)
            )
        except ImportError:
            raise InputError(INSTALL) from None
        self.host, self.port = config.address()
        self.server = uvicorn.Server(
            uvicorn.Config(app, log_level="warning", access_log=False, lifespan="off")
        )
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((self.host, self.port))
        except OSError as exc:
            sock.close()
            raise InputError(
                f"http.listen: {self.host}:{self.port}: cannot listen ({exc.strerror or exc})"
            ) from None
        self.port = sock.getsockname()[1]  # the one given, or the one found for 0
        self._thread = threading.Thread(
            target=self.server.run, kwargs={"sockets": [sock]}, name="http", daemon=True
        )
        self._thread.start()

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}"

    def stop(self) -> None:
        self.server.should_exit = True
        if self._thread is not None:
            self._thread.join(5.0)
