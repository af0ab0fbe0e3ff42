"""The monitor's web server (Starlette on uvicorn, on a thread of its own): the operator's
dashboard, its JSON API (documented by an OpenAPI schema at ``/api/openapi.json``; the pages
use nothing else), health and metrics. Who may use it: :mod:`.auth`.

=========================================  ==================================================
route                                      what
=========================================  ==================================================
``GET /``, ``/rig/RIG``, ``/events``,      the dashboard's pages: every rig at a glance, a
``/health``                                rig, the events, the monitor's health
``GET /login``, ``POST /login``,           the login page (with a token), and leaving
``POST /logout``
``GET /healthz``                           200 while every rig has fresh data and every worker
                                           of the monitor is well, else 503 naming the rigs
                                           and workers that are not (no token: probes)
``GET /api/status``                        per rig: state, health, frames/s, age of the last
                                           frame, counters, FFC, VOx, hottest reading, ROIs,
                                           active alarms, colour scale; storage, broker,
                                           latencies
``GET /api/session``                       who you are and the CSRF token your POSTs carry
``GET /api/events``                        events, newest first: ``limit`` (<= 1000),
                                           ``rig``, ``level``, ``state``, ``before`` (an id)
``GET /api/events/ID``                     one event
``GET /api/events/ID/snapshot.png``,       its overlay, point cloud, and clip (the recording
``cloud.ply``, ``clip.zip``                as one zip); 404 when not kept, 503 (Retry-After)
                                           while the clip is still being recorded
``GET /api/rigs/RIG/overlay.jpg``,         the rig's latest overlay and thermal image
``thermal.png``                            (``width``: scaled down)
``GET /api/rigs/RIG/stream.mjpeg``         its live video as MJPEG (``view``: ``overlay``
                                           or ``thermal``), ``mjpeg.fps`` frames a second;
                                           503 beyond ``mjpeg.max_streams`` at once
``GET /api/rigs/RIG/trend``                its readings over the last hour
``GET /api/rigs/RIG/lines``                its latest line profiles (temperature against
                                           metres along the surface) and isotherm areas;
                                           404 no such rig (or a central dashboard's)
``GET /api/reports/FILE``                  a scheduled inspection report (PDF or HTML) by
                                           its file's name (404: not kept)
``POST /api/ack``                          acknowledge ``{"rig", "rule", "by"}``: 200 with
                                           its events, 404 no such rig or rule, 409 not
                                           raised, 403 a forged request
``POST /api/retire``                       a central dashboard: retire ``{"name"}``, a rig
                                           (``edge1/line3``) or a monitor with all its rigs
                                           (``edge1``) that is gone for good; 409 while it
                                           runs (and on a monitor: rigs leave its config)
``GET /metrics``                           Prometheus' text format (:mod:`.metrics`)
=========================================  ==================================================

Events and their evidence are addressed by id, never by a path.

Every route is guarded by one middleware (:class:`Guard`) that denies by default: only
:data:`PUBLIC` (``/healthz``, the login page and its two static files) answer without the
token. A request without it gets 401 (a page: with a link to the login form); one with a
wrong token, or a session that has expired, gets 401 saying so. The live pictures and streams
(:data:`LIVE_PICTURE`) also take the token as a query (``?token=``), for cameras' clients
that cannot send a header (Home Assistant's MJPEG camera); they only read.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import socket
import tempfile
import threading
import zipfile
from importlib.resources import files
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol
from urllib.parse import quote

from .. import __version__
from ..errors import InputError
from ..io.measurements import jsonable
from .auth import COOKIE, SESSION_S, Auth, Identity
from .config import HttpConfig, MjpegConfig, read_token
from .live import VIEWS
from .logs import logger
from .supervisor import AckRefusedError, ClipNotReadyError
from .workers import Worker

if TYPE_CHECKING:
    from starlette.applications import Starlette
    from starlette.requests import Request
    from starlette.responses import Response

    from .live import Picture, VideoFrame

INSTALL = "the monitor's HTTP server needs the monitor extra: pip install 'thermodepth[monitor]'"
WEB = files("thermodepth.monitor") / "web"
PAGES = {"/": ("overview", "Overview"), "/events": ("events", "Events"),
         "/health": ("health", "Health"), "/rig/{rig:path}": ("rig", "Rig")}  # fmt: skip
"""Each page's path, name (what app.js draws) and title: one template, web/page.html."""
EVIDENCE = {"snapshot.png": "image/png", "cloud.ply": "application/octet-stream",
            "clip.zip": "application/zip"}  # fmt: skip
PICTURES = {"overlay.jpg": ("overlay", "image/jpeg"), "thermal.png": ("thermal", "image/png")}
PUBLIC = frozenset({"/healthz", "/login", "/static/login.js", "/static/style.css"})
"""The only paths that answer without the token (probes, and the way to log in)."""
LIVE_PICTURE = re.compile(r"^/api/rigs/.+/(stream\.mjpeg|overlay\.jpg|thermal\.png)$")
"""The paths whose GET takes the token as a query too (``?token=``): read-only pictures."""
HTTP_LIMIT_S = 30.0
BOUNDARY = "thermodepth-frame"
FIRST_FRAME_S = 10.0
"""How long a new stream waits for its rig's first picture (a running rig's comes within a
quarter of a second of being asked for) before it answers 404."""


class Monitor(Protocol):
    """What the web server asks of a monitor (:class:`~.service.Monitor` is one)."""

    def status(self) -> dict[str, Any]: ...

    def stale_rigs(self) -> list[str]: ...

    def unhealthy_workers(self) -> list[str]: ...

    def events(
        self,
        limit: int = 100,
        rig: str | None = None,
        before_id: int | None = None,
        level: str | None = None,
        state: str | None = None,
    ) -> list[dict[str, Any]]: ...

    def event(self, event_id: int) -> dict[str, Any] | None: ...

    def evidence_file(self, event_id: int, what: str) -> Path | None: ...

    def evidence_of(self, event: dict[str, Any]) -> list[str]: ...

    def picture(self, rig: str, what: str, width: int | None) -> Picture | None: ...

    def video(self, rig: str, view: str, hz: float) -> VideoFrame | None: ...

    def trend(self, rig: str) -> list[dict[str, Any]] | None: ...

    def lines(self, rig: str) -> dict[str, Any] | None: ...
    def report_file(self, name: str) -> Path | None: ...

    def acknowledge(self, rig: str, rule: str, by: str) -> list[dict[str, Any]]: ...

    def retire(self, name: str) -> list[str]: ...


def _json(data: Any, status: int = 200) -> Response:
    from starlette.responses import Response

    body = json.dumps(jsonable(data), separators=(",", ":"))
    return Response(body, status, media_type="application/json")


def _error(message: str, status: int) -> Response:
    return _json({"error": message}, status)


def _zip_of(folder: Path) -> Path:
    """A clip's recording as one zip (stored: its chunks are compressed already), in a
    temporary file the response deletes once sent."""
    fd, name = tempfile.mkstemp(suffix=".zip")
    os.close(fd)
    with zipfile.ZipFile(name, "w", zipfile.ZIP_STORED) as z:
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                z.write(path, Path(folder.name) / path.relative_to(folder))
    return Path(name)


class Guard:
    """The ASGI middleware that asks who calls, once, for every route (module docstring):
    the caller's :class:`~.auth.Identity` goes on to the route as ``request.state.identity``;
    a path outside :data:`PUBLIC` without one is answered 401 here."""

    def __init__(self, app: Any, auth: Auth) -> None:
        self.app, self.auth = app, auth

    async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
        from starlette.requests import HTTPConnection

        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        conn = HTTPConnection(scope)
        query = None
        if scope["method"] == "GET" and LIVE_PICTURE.match(scope["path"]):
            query = conn.query_params.get("token")
        who = self.auth.identity(conn.headers, conn.cookies, query)
        if who is None and scope["path"] not in PUBLIC:
            await refusal(conn, self.auth)(scope, receive, send)
            return
        scope.setdefault("state", {})["identity"] = who
        await self.app(scope, receive, send)


def refusal(conn: Any, auth: Auth) -> Response:
    """The 401 of a request without a way in: why (no token, a wrong one, a session that
    ended), as JSON for the API and as a page that leads to the login form for a browser."""
    from starlette.responses import HTMLResponse

    headers = conn.headers
    if headers.get("authorization") or (
        LIVE_PICTURE.match(conn.url.path) and "token" in conn.query_params
    ):
        why, challenge = "wrong token", 'Bearer realm="thermodepth", error="invalid_token"'
    elif conn.cookies.get(COOKIE):
        why, challenge = "your session has ended: log in again", 'Bearer realm="thermodepth"'
    else:
        why, challenge = "a token is needed", 'Bearer realm="thermodepth"'
    if conn.scope["method"] == "GET" and "text/html" in headers.get("accept", ""):
        target = f"/login?next={quote(conn.url.path)}"
        page = (
            f'<!doctype html><meta http-equiv="refresh" content="0; url={target}">'
            f'<title>log in</title><p>{why}: <a href="{target}">log in</a></p>'
        )
        response: Response = HTMLResponse(page, 401)
    else:
        response = _error(why, 401)
    response.headers["WWW-Authenticate"] = challenge
    return response


class Streams:
    """The MJPEG streams of one server: at most ``config.max_streams`` at once (:meth:`enter`
    says whether one more may begin), each ended once ``closing`` is set (the server stops)."""

    def __init__(self, config: MjpegConfig) -> None:
        self.config = config
        self.closing = threading.Event()
        self.open = 0
        self.refused = 0
        self._lock = threading.Lock()

    def enter(self) -> bool:
        with self._lock:
            if self.open >= self.config.max_streams:
                self.refused += 1
                return False
            self.open += 1
            return True

    def leave(self) -> None:
        with self._lock:
            self.open -= 1

    def status(self) -> dict[str, Any]:
        return {"open": self.open, "max": self.config.max_streams, "refused": self.refused}


def _part(frame: VideoFrame) -> bytes:
    """One JPEG of a multipart stream, its boundary first."""
    head = f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\nContent-Length: {len(frame.jpeg)}\r\n"
    if frame.time_s is not None:
        head += f"X-Capture-Time: {frame.time_s:.3f}\r\n"
    return head.encode() + b"\r\n" + frame.jpeg + b"\r\n"


def build_app(monitor: Monitor, auth: Auth, streams: Streams | None = None) -> Starlette:
    """The Starlette application of the routes (module docstring); ``streams``: its MJPEG
    streams (default: ``mjpeg``'s defaults)."""
    from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, generate_latest
    from starlette.applications import Starlette
    from starlette.background import BackgroundTask
    from starlette.concurrency import run_in_threadpool
    from starlette.responses import FileResponse, HTMLResponse, Response, StreamingResponse
    from starlette.routing import Mount, Route
    from starlette.schemas import SchemaGenerator
    from starlette.staticfiles import StaticFiles

    from .metrics import collector

    mjpeg = streams or Streams(MjpegConfig())
    registry = CollectorRegistry()
    registry.register(collector(monitor.status))
    schemas = SchemaGenerator(
        {"openapi": "3.0.0", "info": {"title": "thermodepth monitor", "version": __version__}}
    )

    def who(request: Request) -> Identity:
        """The caller, as :class:`Guard` found it (every route but PUBLIC has one)."""
        identity: Identity = request.state.identity
        return identity

    template = (WEB / "page.html").read_text(encoding="utf-8")

    def page(name: str, title: str) -> Any:
        html = template.replace("{{page}}", name).replace("{{title}}", title)

        async def serve(request: Request) -> Response:
            return HTMLResponse(html)

        return serve

    async def login_page(request: Request) -> Response:
        return HTMLResponse((WEB / "login.html").read_text(encoding="utf-8"))

    async def login(request: Request) -> Response:
        try:
            body = await request.json()
        except ValueError:
            body = None
        if not isinstance(body, dict) or not isinstance(body.get("token"), str):
            return _error('expected {"token": ..., "name": ...}', 400)
        name = str(body.get("name") or "").strip() or "operator"
        session = auth.login(body["token"], name)
        if session is None:
            return _error("wrong token", 401)
        response = _json({"name": name})
        response.set_cookie(COOKIE, session, max_age=int(SESSION_S), httponly=True,
                            samesite="strict", secure=auth.secure)  # fmt: skip
        return response

    async def logout(request: Request) -> Response:
        auth.logout(request.cookies.get(COOKIE))
        response = _json({"ok": True})
        response.delete_cookie(COOKIE)
        return response

    async def healthz(request: Request) -> Response:
        """
        responses:
          200: {description: every rig has fresh data}
          503: {description: the rigs without fresh data}
        """
        stale, down = monitor.stale_rigs(), monitor.unhealthy_workers()
        if stale or down:
            return _json({"status": "stale" if stale else "unwell", "rigs": stale,
                          "workers": down}, 503)  # fmt: skip
        return _json({"status": "ok"})

    async def status(request: Request) -> Response:
        """
        responses:
          200: {description: "per rig: state, health, fps, last_frame_age_s, reconnects,
            stalls, seconds_without_data, ffc, vox_temp_c, hottest, rois, active_alarms,
            temp_range_c; storage, mqtt, event_counts, latency_s"}
          401: {description: a token is needed}
        """
        return _json(monitor.status())

    async def session(request: Request) -> Response:
        """
        responses:
          200: {description: "who you are (auth: open, session or bearer; name) and the
            CSRF token your POSTs carry as X-CSRF-Token"}
        """
        you = who(request)
        return _json({"auth": you.kind, "name": you.name, "csrf": you.csrf})

    async def events(request: Request) -> Response:
        """
        parameters:
          - {name: limit, in: query, schema: {type: integer, default: 100, maximum: 1000}}
          - {name: rig, in: query, schema: {type: string}}
          - {name: level, in: query, schema: {type: string, enum: [warning, alarm]}}
          - {name: state, in: query,
             schema: {type: string, enum: [alarm, escalated, acknowledged, clear]}}
          - {name: before, in: query, description: only older than this id,
             schema: {type: integer}}
        responses:
          200: {description: "events, newest first, each with the evidence this server
            gives for it (evidence: snapshot.png, clip.zip, cloud.ply)"}
          400: {description: a bad parameter}
        """
        q = request.query_params
        try:
            limit = min(int(q.get("limit", "100")), 1000)
            before = int(q["before"]) if "before" in q else None
            if limit < 1:
                raise ValueError
        except ValueError:
            return _error("limit and before are whole numbers, limit >= 1", 400)
        found = monitor.events(limit, q.get("rig"), before, q.get("level"), q.get("state"))
        return _json([{**e, "evidence": monitor.evidence_of(e)} for e in found])

    async def event(request: Request) -> Response:
        """
        responses:
          200: {description: the event}
          404: {description: no such event}
        """
        found = monitor.event(request.path_params["id"])
        if found is None:
            return _error("no such event", 404)
        return _json({**found, "evidence": monitor.evidence_of(found)})

    def evidence(request: Request) -> Response:
        """
        responses:
          200: {description: "the event's overlay (snapshot.png), point cloud (cloud.ply)
            or clip (clip.zip: the recording)"}
          404: {description: no such event, or its evidence is not kept}
          503: {description: the clip is still being recorded (Retry-After says when to ask)}
        """
        what = request.path_params["what"]
        if what not in EVIDENCE:
            return _error(f"expected one of {', '.join(EVIDENCE)}", 404)
        try:
            path = monitor.evidence_file(request.path_params["id"], what)
        except ClipNotReadyError as exc:
            busy = _error(f"{exc}: ask again in a few seconds", 503)
            busy.headers["Retry-After"] = "2"
            return busy
        if path is None:
            return _error("not kept", 404)
        name = f"event-{request.path_params['id']}-{what}"
        if what == "clip.zip":
            packed = _zip_of(path)
            return FileResponse(packed, media_type=EVIDENCE[what], filename=name,
                                background=BackgroundTask(packed.unlink))  # fmt: skip
        return FileResponse(path, media_type=EVIDENCE[what], filename=name)

    def report(request: Request) -> Response:
        """
        responses:
          200: {description: "a scheduled inspection report (PDF or HTML) by its file's name"}
          404: {description: no such report kept}
        """
        name = request.path_params["name"]
        path = monitor.report_file(name)
        if path is None:
            return _error("no such report kept", 404)
        media = "application/pdf" if path.suffix == ".pdf" else "text/html; charset=utf-8"
        return FileResponse(path, media_type=media, filename=name)

    def picture(request: Request) -> Response:
        """
        parameters:
          - {name: width, in: query, schema: {type: integer}}
        responses:
          200: {description: "the rig's latest overlay (overlay.jpg) or thermal image
            (thermal.png); X-Capture-Time: its frame's capture time (Unix s), when known"}
          404: {description: no such rig, or no frame yet}
        """
        what = request.path_params["what"]
        if what not in PICTURES:
            return _error(f"expected one of {', '.join(PICTURES)}", 404)
        try:
            width = int(request.query_params["width"]) if "width" in request.query_params else None
        except ValueError:
            return _error("width: a whole number of pixels", 400)
        kind, media = PICTURES[what]
        found = monitor.picture(request.path_params["rig"], kind, width)
        if found is None:
            return _error("no such rig, or no frame yet", 404)
        headers = {"Cache-Control": "no-store"}
        if found.time_s is not None:
            headers["X-Capture-Time"] = f"{found.time_s:.3f}"
        return Response(found.data, media_type=media, headers=headers)

    class Stream(StreamingResponse):
        """A stream that gives its place back however it ends (the client gone, the server
        stopping)."""

        async def __call__(self, scope: Any, receive: Any, send: Any) -> None:
            try:
                await super().__call__(scope, receive, send)
            finally:
                mjpeg.leave()

    async def stream(request: Request) -> Response:
        """
        parameters:
          - {name: view, in: query, schema: {type: string, enum: [overlay, thermal],
             default: overlay}}
          - {name: token, in: query, description: the token, for clients that cannot send
             a header, schema: {type: string}}
        responses:
          200: {description: "the rig's live video: multipart/x-mixed-replace of JPEG
            pictures, mjpeg.fps a second (X-Frame-Rate), each with its title and colour scale
            and X-Capture-Time; each client gets the latest picture when it can take one"}
          400: {description: a bad view}
          404: {description: no such rig, or no frame yet}
          503: {description: as many streams as mjpeg.max_streams are open}
        """
        rig, view = request.path_params["rig"], request.query_params.get("view", "overlay")
        if view not in VIEWS:
            return _error(f"view: expected one of {', '.join(VIEWS)}", 400)
        fps = mjpeg.config.fps
        loop = asyncio.get_running_loop()
        end = loop.time() + FIRST_FRAME_S
        while await run_in_threadpool(monitor.video, rig, view, fps) is None:
            if loop.time() > end:
                return _error("no such rig, or no frame yet", 404)
            await asyncio.sleep(0.1)
        if not mjpeg.enter():
            busy = _error(f"{mjpeg.config.max_streams} streams are open (mjpeg.max_streams)", 503)
            busy.headers["Retry-After"] = "10"
            return busy

        async def parts() -> Any:
            due = loop.time()
            while not mjpeg.closing.is_set():
                frame = await run_in_threadpool(monitor.video, rig, view, fps)
                if frame is not None:
                    # sent when the client can take it (the server waits while its socket is
                    # full): a slow client skips pictures, nothing queues for it
                    yield await run_in_threadpool(_part, frame)
                due = max(due + 1.0 / fps, loop.time())
                await asyncio.sleep(due - loop.time())

        headers = {"Cache-Control": "no-store", "X-Frame-Rate": f"{fps:g}"}
        return Stream(parts(), media_type=f"multipart/x-mixed-replace; boundary={BOUNDARY}",
                      headers=headers)  # fmt: skip

    async def trend(request: Request) -> Response:
        """
        responses:
          200: {description: "the rig's readings every 10 s over the last hour: time_s,
            hottest_c, rois (each ROI's max, C)"}
          404: {description: no such rig}
        """
        found = monitor.trend(request.path_params["rig"])
        return _json(found) if found is not None else _error("no such rig", 404)

    async def lines(request: Request) -> Response:
        """
        responses:
          200: {description: "the rig's latest line profiles (name, length_m, max_c, max_at_m,
            max_px, n, gap_px, distance_m [], temp_c []) and isotherms (name, above_c,
            area_cm2, n, max_c, mean_c)"}
          404: {description: no such rig, or none kept here (a central dashboard)}
        """
        found = monitor.lines(request.path_params["rig"])
        return _json(found) if found is not None else _error("no such rig", 404)

    async def ack(request: Request) -> Response:
        """
        requestBody:
          content:
            application/json:
              schema: {type: object, required: [rig, rule],
                       properties: {rig: {type: string}, rule: {type: string},
                                    by: {type: string}}}
        responses:
          200: {description: the acknowledgement's events}
          400: {description: a malformed body}
          403: {description: a forged request (no JSON, no CSRF token)}
          404: {description: no such rig or rule}
          409: {description: not raised}
        """
        you = who(request)
        forged = auth.forged(you, request.headers)
        if forged is not None:
            return _error(forged, 403)
        try:
            body = await request.json()
        except ValueError:
            body = None
        if not isinstance(body, dict) or not all(
            isinstance(body.get(k), str) for k in ("rig", "rule")
        ):
            return _error('expected {"rig": ..., "rule": ..., "by": ...}', 400)
        by = str(body.get("by") or you.name or "").strip()
        if not by:
            return _error("by: say who acknowledges", 400)
        try:
            # a central dashboard waits for the rig's monitor: not on the event loop
            events = await run_in_threadpool(monitor.acknowledge, body["rig"], body["rule"], by)
            return _json(events)
        except AckRefusedError as exc:
            return _error(exc.message, exc.status)

    async def retire(request: Request) -> Response:
        """
        requestBody:
          content:
            application/json:
              schema: {type: object, required: [name], properties: {name: {type: string}}}
        responses:
          200: {description: "the rigs retired: {retired: [...]}"}
          400: {description: a malformed body}
          403: {description: a forged request}
          404: {description: no such rig or monitor}
          409: {description: it still runs, or this is not a central dashboard}
        """
        forged = auth.forged(who(request), request.headers)
        if forged is not None:
            return _error(forged, 403)
        try:
            body = await request.json()
        except ValueError:
            body = None
        if not isinstance(body, dict) or not isinstance(body.get("name"), str):
            return _error('expected {"name": RIG or MONITOR}', 400)
        try:
            return _json({"retired": await run_in_threadpool(monitor.retire, body["name"])})
        except AckRefusedError as exc:
            return _error(exc.message, exc.status)

    async def metrics(request: Request) -> Response:
        return Response(generate_latest(registry), media_type=CONTENT_TYPE_LATEST)

    async def openapi(request: Request) -> Response:
        # Starlette's own response is YAML; the path promises JSON.
        return _json(schemas.get_schema(routes=request.app.routes))

    routes = [
        *(Route(path, page(name, title)) for path, (name, title) in PAGES.items()),
        Route("/login", login_page),
        Route("/login", login, methods=["POST"]),
        Route("/logout", logout, methods=["POST"]),
        Route("/healthz", healthz),
        Route("/api/status", status),
        Route("/api/session", session),
        Route("/api/events", events),
        Route("/api/events/{id:int}", event),
        Route("/api/events/{id:int}/{what}", evidence),
        Route("/api/reports/{name}", report),
        Route("/api/rigs/{rig:path}/trend", trend),  # a central dashboard's rigs: EDGE/RIG
        Route("/api/rigs/{rig:path}/lines", lines),
        Route("/api/rigs/{rig:path}/stream.mjpeg", stream),
        Route("/api/rigs/{rig:path}/{what}", picture),
        Route("/api/ack", ack, methods=["POST"]),
        Route("/api/retire", retire, methods=["POST"]),
        Route("/api/openapi.json", openapi, include_in_schema=False),
        Route("/metrics", metrics),
        Mount("/static", StaticFiles(directory=str(WEB)), name="static"),
    ]
    from starlette.middleware import Middleware

    return Starlette(routes=routes, middleware=[Middleware(Guard, auth=auth)])


class HttpServer:
    """The application served by uvicorn on a supervised worker of its own (restarted when
    it fails; over TLS when ``http.tls_cert`` and ``tls_key`` are given); ``start`` binds the
    address first, so that one taken is one InputError line."""

    def __init__(
        self, monitor: Monitor, config: HttpConfig, mjpeg: MjpegConfig | None = None
    ) -> None:
        try:
            import uvicorn  # noqa: F401

            token = None if config.token_file is None else read_token(config.token_file)
            self.tls = config.tls_cert is not None
            self.streams = Streams(mjpeg or MjpegConfig())
            self.app = build_app(monitor, Auth.from_env(token, secure=self.tls), self.streams)
        except ImportError:
            raise InputError(INSTALL) from None
        self.config = config
        self.host, self.port = config.address()
        self.server: Any = None
        self._sock: socket.socket | None = None
        self.worker = Worker("http", self._serve, None, HTTP_LIMIT_S, logger("http"))

    def _bind(self) -> socket.socket:
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
        sock.listen(128)  # so that a client early on waits in the queue, not refused
        self.port = sock.getsockname()[1]  # the one given, or the one found for 0
        return sock

    def start(self) -> None:
        self._sock = self._bind()
        self.worker.start()

    def _serve(self, worker: Worker) -> None:
        import uvicorn

        if self._sock is None or self._sock.fileno() == -1:  # closed by a server that failed
            self._sock = self._bind()
        cert, key = self.config.tls_cert, self.config.tls_key
        self.server = uvicorn.Server(
            uvicorn.Config(
                self.app,
                log_level="warning",
                access_log=False,
                lifespan="off",
                ssl_certfile=None if cert is None else str(cert),
                ssl_keyfile=None if key is None else str(key),
            )
        )
        if not worker.stopping.is_set():
            self.server.run(sockets=[self._sock])

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'https' if self.tls else 'http'}://{host}:{self.port}"

    def stop(self, reason: str = "stopped") -> None:
        self.worker.stopping.set()
        self.streams.closing.set()  # the streams end, so that the server's end need not wait
        if self.server is not None:
            self.server.should_exit = True
        self.worker.stop()
