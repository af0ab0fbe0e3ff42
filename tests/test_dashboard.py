"""The dashboard's server over HTTP (httpx): logging in with a token, session cookies, CSRF,
the evidence of an event by its id (and nothing by a path), live pictures, trends, the
OpenAPI schema, TLS."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Any
from unittest.mock import patch

import pytest

pytest.importorskip("starlette", reason="the dashboard needs the monitor extra (starlette)")
pytest.importorskip("uvicorn", reason="the dashboard needs the monitor extra (uvicorn)")

import httpx

from monitor_helpers import FLAPPING, monitor_config, settings_file, wait_for
from thermodepth.monitor import Monitor, load_config
from thermodepth.monitor.auth import COOKIE
from thermodepth.sources import open_source

ROIS = "rois:\n  - {name: plate, rect: [560, 280, 720, 440]}\n"


@pytest.fixture(scope="module")
def running(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """A monitor of one simulated rig with a token, its events and clips being made."""
    folder = tmp_path_factory.mktemp("dashboard")
    settings_file(folder, FLAPPING + ROIS)
    (folder / "token").write_text("s3cret\n")
    path = monitor_config(folder, [{"name": "a", "source": "sim", "settings": "s.yaml"}],
                          http={"token_file": "token"})  # fmt: skip
    monitor = Monitor(load_config(path))
    monitor.start()
    try:
        wait_for(lambda: any(e.get("clip") for e in monitor.store.events(100)))
        yield monitor, folder
    finally:
        monitor.stop()


def client(monitor: Monitor, **kw: Any) -> httpx.Client:
    return httpx.Client(base_url=monitor.http.url, timeout=10, **kw)


BEARER = {"Authorization": "Bearer s3cret"}


def test_pages_want_a_login_and_the_login_gives_a_session(running: Any) -> None:
    monitor, _ = running
    with client(monitor) as c:
        html = {"Accept": "text/html"}  # a browser: a page that leads to the login form
        assert c.get("/", headers=html).status_code == 401
        assert 'url=/login?next=/"' in c.get("/", headers=html).text
        assert 'url=/login?next=/events"' in c.get("/events", headers=html).text
        assert c.get("/login").status_code == 200
        assert c.get("/healthz").status_code in (200, 503)  # probes need no token
        assert c.get("/api/status").status_code == 401
        assert c.post("/login", json={"token": "wrong", "name": "x"}).status_code == 401
        ok = c.post("/login", json={"token": "s3cret", "name": "operator jane"})
        assert ok.status_code == 200
        cookie = ok.headers["set-cookie"]
        assert cookie.startswith(f"{COOKIE}=")
        assert "HttpOnly" in cookie and "SameSite=strict" in cookie and "Secure" not in cookie
        for page in ("/", "/rig/a", "/events", "/health"):
            r = c.get(page)
            assert r.status_code == 200 and '<script type="module" src="/static/app.js">' in r.text
        me = c.get("/api/session").json()
        assert me["auth"] == "session" and me["name"] == "operator jane" and len(me["csrf"]) > 20
        c.post("/logout")
        assert c.get("/api/status").status_code == 401  # the session is gone


def test_acknowledge_needs_the_sessions_csrf_token(running: Any) -> None:
    monitor, _ = running
    wait_for(lambda: "latched" in {a["rule"] for a in monitor.runners["a"].raised()})
    with client(monitor) as c:
        c.post("/login", json={"token": "s3cret", "name": "operator jane"})
        csrf = c.get("/api/session").json()["csrf"]
        body = {"rig": "a", "rule": "latched"}
        assert c.post("/api/ack", json=body).status_code == 403  # a forged request
        assert c.post("/api/ack", json=body, headers={"X-CSRF-Token": "guess"}).status_code == 403
        form = c.post("/api/ack", content=json.dumps(body),
                      headers={"X-CSRF-Token": csrf, "Content-Type": "text/plain"})  # fmt: skip
        assert form.status_code == 403
        ok = c.post("/api/ack", json=body, headers={"X-CSRF-Token": csrf})
        assert (
            ok.status_code == 200 and ok.json()[0]["by"] == "operator jane"
        )  # who, from the login
    with client(monitor, headers=BEARER) as c:  # a bearer token needs no CSRF token
        again = c.post("/api/ack", json={**body, "by": "scada"})
        assert again.status_code == 200  # still hot, so still raised: acknowledged again
    acked = [e for e in monitor.store.events(1000) if e["event"] == "acknowledged"]
    assert [e["by"] for e in acked] == ["scada", "operator jane"]


def test_evidence_by_event_id_and_nothing_by_a_path(running: Any, tmp_path: Path) -> None:
    monitor, folder = running
    event = next(e for e in monitor.store.events(1000) if e.get("clip"))
    wait_for(lambda: (folder / "store" / "clips" / event["clip"] / "overlay.png").exists())
    with client(monitor, headers=BEARER) as c:
        one = c.get(f"/api/events/{event['id']}").json()
        assert one["clip"] == event["clip"]
        assert one["evidence"] == ["snapshot.png", "clip.zip", "cloud.ply"]
        png = c.get(f"/api/events/{event['id']}/snapshot.png")
        assert png.status_code == 200 and png.content.startswith(b"\x89PNG")
        ply = c.get(f"/api/events/{event['id']}/cloud.ply")
        assert ply.content.startswith(b"ply\n")
        clip_url = f"/api/events/{event['id']}/clip.zip"
        folder_of_clip = folder / "store" / "clips" / event["clip"]
        with patch.object(monitor.evidence, "active_folders", lambda: {folder_of_clip}):
            busy = c.get(clip_url)  # still being recorded: not served torn
        assert busy.status_code == 503 and busy.headers["retry-after"] == "2"
        assert "still being recorded" in busy.json()["error"]
        clip = wait_for(lambda: (r := c.get(clip_url)).status_code == 200 and r)
        assert clip.headers["content-type"] == "application/zip"
        with zipfile.ZipFile(io.BytesIO(clip.content)) as z:
            z.extractall(tmp_path)
        with open_source(f"recording:{tmp_path / 'clip.zarr'}") as src:
            assert len(list(src)) >= 1  # the clip as a recording that replays
        for bad in (
            "/api/events/..%2F..%2F..%2Fetc%2Fpasswd/snapshot.png",
            f"/api/events/{event['id']}/..%2F..%2F..%2Fetc%2Fpasswd",
            f"/api/events/{event['id']}/overlay.png",
            "/api/events/999999/snapshot.png",
            "/static/..%2F..%2F..%2F..%2Fetc%2Fpasswd",
        ):
            assert c.get(bad).status_code == 404, bad
        # a row whose clip would lead out of the clips' folder leads nowhere
        (folder / "store" / "secret").mkdir(exist_ok=True)
        (folder / "store" / "secret" / "overlay.png").write_bytes(b"\x89PNG secret")
        crafted = {**event, "clip": "../secret", "event": "alarm"}
        crafted.pop("id")
        bad_id = monitor.store.add(crafted)
        assert c.get(f"/api/events/{bad_id}/snapshot.png").status_code == 404


def test_live_pictures_trend_and_the_schema(running: Any) -> None:
    monitor, _ = running
    with client(monitor, headers=BEARER) as c:
        overlay = wait_for(lambda: (r := c.get("/api/rigs/a/overlay.jpg")).status_code == 200 and r)
        assert (
            overlay.content.startswith(b"\xff\xd8")
            and overlay.headers["cache-control"] == "no-store"
        )
        shown_s = float(overlay.headers["x-capture-time"])  # its frame's, as the trend's
        assert shown_s >= 0 and monitor.runners["a"].status.frames > 0
        small = c.get("/api/rigs/a/overlay.jpg", params={"width": 320})
        import cv2
        import numpy as np

        img = cv2.imdecode(np.frombuffer(small.content, np.uint8), cv2.IMREAD_COLOR)
        assert img.shape == (180, 320, 3)
        thermal = c.get("/api/rigs/a/thermal.png")
        assert thermal.content.startswith(b"\x89PNG")
        assert c.get("/api/rigs/z/overlay.jpg").status_code == 404
        assert c.get("/api/rigs/a/overlay.gif").status_code == 404
        trend = c.get("/api/rigs/a/trend").json()
        assert (
            trend
            and set(trend[0]) == {"time_s", "hottest_c", "rois"}
            and "plate" in trend[0]["rois"]
        )
        schema = c.get("/api/openapi.json").json()
        assert schema["openapi"].startswith("3.")
        for path in ("/api/status", "/api/events", "/api/events/{id}", "/api/ack", "/healthz"):
            assert path in schema["paths"], path
        # a busy machine can leave the rig stale a moment: its health waited for
        status = wait_for(
            lambda: (r := c.get("/api/status").json()["rigs"][0])["health"] == "ok" and r
        )
        assert status["temp_range_c"] and "plate" in status["rois"]


def test_tls_with_a_certificate(tmp_path: Path) -> None:
    import datetime
    import ipaddress
    import ssl

    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import rsa
    from cryptography.x509.oid import NameOID

    key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    name = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, "127.0.0.1")])
    now = datetime.datetime.now(datetime.timezone.utc)
    cert = (
        x509.CertificateBuilder().subject_name(name).issuer_name(name)
        .public_key(key.public_key()).serial_number(1)
        .not_valid_before(now).not_valid_after(now + datetime.timedelta(days=1))
        .add_extension(x509.SubjectAlternativeName(
            [x509.IPAddress(ipaddress.ip_address("127.0.0.1"))]), critical=False)
        .sign(key, hashes.SHA256())
    )  # fmt: skip
    (tmp_path / "cert.pem").write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    (tmp_path / "key.pem").write_bytes(key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
        serialization.NoEncryption(),
    ))  # fmt: skip
    (tmp_path / "token").write_text("s3cret\n")
    path = monitor_config(tmp_path, [{"name": "a", "source": "sim"}],
                          http={"token_file": "token", "tls_cert": "cert.pem",
                                "tls_key": "key.pem"})  # fmt: skip
    monitor = Monitor(load_config(path))
    monitor.start()
    try:
        assert monitor.http.url.startswith("https://")
        trusted = ssl.create_default_context(cafile=tmp_path / "cert.pem")
        with httpx.Client(base_url=monitor.http.url, verify=trusted) as c:
            assert c.get("/healthz").status_code in (200, 503)
            login = c.post("/login", json={"token": "s3cret", "name": "jane"})
            assert "Secure" in login.headers["set-cookie"]  # cookies only over TLS
    finally:
        monitor.stop()
