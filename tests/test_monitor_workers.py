"""The monitor guards its own loops as it guards its rigs: each worker (the clock, the storage
sweep, the evidence painter, the HTTP server, the MQTT outbox and snapshots, OPC UA) failing
on purpose comes back with its restart counted, nothing is lost, and the health says so
meanwhile (``/api/status``, ``/metrics``, ``/healthz``, systemd's watchdog)."""

from __future__ import annotations

import asyncio
import logging
import sqlite3
import threading
import time
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("starlette", reason="the monitor needs the monitor extra (starlette)")

import httpx

from monitor_helpers import Notifications, monitor_config, settings_file, wait_for
from thermodepth.monitor import Monitor, load_config
from thermodepth.monitor import service as service_mod
from thermodepth.monitor.storage import CLIPS, stamp
from thermodepth.monitor.workers import Worker

# -- a worker alone ---------------------------------------------------------------------------


def test_a_failing_loop_is_logged_restarted_and_counted(caplog: pytest.LogCaptureFixture) -> None:
    runs: list[float] = []

    def loop(worker: Worker) -> None:
        runs.append(time.monotonic())
        if len(runs) <= 2:
            raise ValueError(f"boom {len(runs)}")
        while not worker.stopping.wait(0.05):
            worker.beat()

    worker = Worker("sweeper", loop, every_s=0.5, limit_s=0.5)
    with caplog.at_level(logging.ERROR, logger="thermodepth.monitor"):
        worker.start()
        wait_for(lambda: len(runs) == 3 and worker.state == "running")
        worker.stop()
    assert worker.restarts == 2 and worker.last_error == "ValueError: boom 2"
    assert worker.state == "stopped"
    failed = [r for r in caplog.records if "worker sweeper failed" in r.getMessage()]
    assert len(failed) == 2 and all(r.exc_info for r in failed)  # with its traceback
    assert runs[2] - runs[1] >= 2.0 - 0.05  # the backoff grows: 1 s, then 2 s


def test_a_worker_that_stops_beating_is_hung_and_unhealthy() -> None:
    release = threading.Event()

    def stuck(worker: Worker) -> None:
        worker.beat()
        release.wait()  # a lock never released, say
        while not worker.stopping.wait(0.05):
            worker.beat()

    worker = Worker("painter", stuck, every_s=0.1, limit_s=0.2)
    worker.start()
    try:
        wait_for(lambda: not worker.healthy(time.monotonic()))
        assert worker.as_dict(time.monotonic())["state"] == "hung"
        release.set()
        wait_for(lambda: worker.healthy(time.monotonic()))
    finally:
        release.set()
        worker.stop()
    assert worker.restarts == 0  # hung is not failed: systemd restarts what hangs


def test_a_loop_that_returns_while_it_should_run_is_a_failure() -> None:
    calls: list[int] = []

    def quits(worker: Worker) -> None:
        calls.append(1)
        if len(calls) > 1:
            worker.stopping.wait()

    worker = Worker("http", quits, every_s=None, limit_s=10)
    worker.start()
    wait_for(lambda: len(calls) == 2)
    worker.stop()
    assert worker.restarts == 1 and "returned while it should run" in str(worker.last_error)


# -- in a running monitor -----------------------------------------------------------------------


def once(fail: Exception, then: Any) -> Any:
    """A stand-in that raises ``fail`` the first time it is called, then is ``then``."""
    calls = [0]

    def call(*args: Any, **kwargs: Any) -> Any:
        calls[0] += 1
        if calls[0] == 1:
            raise fail
        return then(*args, **kwargs)

    return call


def answer(client: httpx.Client, path: str) -> int | None:
    """The status a GET of ``path`` gets (None: the connection refused)."""
    try:
        return client.get(path).status_code
    except httpx.ConnectError:
        return None


def workers_of(client: httpx.Client) -> dict[str, dict[str, Any]]:
    return {w["name"]: w for w in client.get("/api/status").json()["workers"]}


@pytest.fixture
def running(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Any:
    """A monitor of one simulated rig whose storage is swept every 0.2 s (not 30), told to
    systemd's stand-in with a watchdog every 0.1 s."""
    monkeypatch.setattr(service_mod, "SWEEP_S", 0.2)
    notes = Notifications(tmp_path / "notify")
    monkeypatch.setenv("NOTIFY_SOCKET", str(notes.path))
    monkeypatch.setenv("WATCHDOG_USEC", "200000")
    path = monitor_config(
        tmp_path,
        [{"name": "a", "source": "sim", "settings": settings_file(tmp_path).name}],
        storage={"retention_days": 1},
    )
    monitor = Monitor(load_config(path))
    monitor.start()
    client = httpx.Client(base_url=monitor.http.url, timeout=30)
    try:
        wait_for(lambda: client.get("/healthz").status_code == 200)  # the rig's data fresh
        yield monitor, client, notes, tmp_path
    finally:
        client.close()
        monitor.stop()


def test_a_store_error_in_the_sweep_restarts_it_and_loses_nothing(
    running: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    monitor, client, _, folder = running
    # a clip two days old, and its event: the sweep deletes it and tells the event
    old = folder / "store" / CLIPS / "a" / f"{stamp(time.time() - 2 * 86400)}-hot"
    old.mkdir(parents=True)
    clip = f"a/{old.name}"
    event = {"rig": "a", "rule": "hot", "level": "alarm", "event": "alarm", "clip": clip,
             "time_utc": "2026-11-26T10:00:00+00:00"}  # fmt: skip
    event_id = monitor.store.add(event)
    locked = sqlite3.OperationalError("database is locked")
    retention = monitor.retention  # the event store's clip_deleted, as the sweep calls it
    monkeypatch.setattr(retention, "clip_deleted", once(locked, retention.clip_deleted))
    storage = wait_for(lambda: (w := workers_of(client)["storage"])["restarts"] == 1 and w)
    assert storage["last_error"] == "OperationalError: database is locked"
    wait_for(lambda: workers_of(client)["storage"]["state"] == "running")
    wait_for(lambda: not old.exists())  # the next sweep did what the failed one had not
    assert monitor.store.event(event_id)["clip_kept"] is False  # and the event says so
    metrics = client.get("/metrics").text
    assert 'thermodepth_worker_restarts_total{worker="storage"} 1.0' in metrics


def test_the_clock_fails_and_watches_again(running: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monitor, client, notes, _ = running
    real = monitor._watch
    monkeypatch.setattr(monitor, "_watch", once(RuntimeError("a bug"), real))
    wait_for(lambda: workers_of(client)["clock"]["restarts"] == 1)
    wait_for(lambda: workers_of(client)["clock"]["state"] == "running")
    notes.got.clear()
    wait_for(lambda: notes.has("WATCHDOG=1"))  # it feeds systemd again
    # and watches the rig again: a source gone quiet is seen as a stall
    stalls = monitor.runners["a"].status.stalls
    source = monitor.runners["a"].source
    assert source is not None
    monkeypatch.setattr(source.inner, "events", lambda: iter(threading.Event().wait, True))
    monitor.runners["a"].abort_stalled("told by the test")  # the reopened source is a new one
    wait_for(lambda: monitor.runners["a"].status.stalls > stalls)


def test_a_worker_down_past_its_limit_is_unhealthy_and_systemd_is_not_fed(
    running: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    monitor, client, notes, _ = running
    painter = monitor.workers.all["evidence pictures"]
    monkeypatch.setattr(painter, "limit_s", 0.0)  # any time down is too long, here
    broken = threading.Event()
    broken.set()
    real_get = monitor.evidence._pictures.get

    def get(*args: Any, **kwargs: Any) -> Any:
        if broken.is_set():
            raise RuntimeError("a broken queue")
        return real_get(*args, **kwargs)

    monkeypatch.setattr(monitor.evidence._pictures, "get", get)
    sick = wait_for(lambda: (r := client.get("/healthz")).status_code == 503 and r.json())
    assert sick == {"status": "unwell", "rigs": [], "workers": ["evidence pictures"]}
    metrics = client.get("/metrics").text
    assert 'thermodepth_worker_up{worker="evidence pictures"} 0.0' in metrics
    # from the clock's next round on, no watchdog: systemd would restart the monitor
    clock = monitor.workers.all["clock"]
    seen = time.monotonic()
    wait_for(lambda: clock.last_beat_mono > seen + 0.3)
    notes.read()
    notes.got.clear()
    later = clock.last_beat_mono
    wait_for(lambda: clock.last_beat_mono > later + 1.0)  # four of its rounds at least
    assert not notes.has("WATCHDOG=1")
    broken.clear()  # it recovers: healthy again, systemd fed again
    wait_for(lambda: client.get("/healthz").status_code == 200)
    wait_for(lambda: notes.has("WATCHDOG=1"))
    assert painter.restarts >= 1


def test_the_painter_and_the_http_server_come_back(
    running: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    monitor, client, _, _ = running
    queue = monitor.evidence._pictures
    monkeypatch.setattr(queue, "get", once(RuntimeError("a broken queue"), queue.get))  # type: ignore[method-assign]
    wait_for(lambda: workers_of(client)["evidence pictures"]["restarts"] == 1)
    # its pictures are drawn again: an event's clip gets its overlay
    wait_for(lambda: any(
        (monitor.config.storage.path / CLIPS / e["clip"] / "overlay.png").exists()
        for e in monitor.store.events(200) if e.get("clip")
    ))  # fmt: skip
    # the HTTP server's loop ends under it: it serves again, on the same address
    url = monitor.http.url
    monitor.http.server.should_exit = True
    wait_for(lambda: monitor.workers.all["http"].restarts == 1)
    with httpx.Client(base_url=url, timeout=30) as again:
        assert wait_for(lambda: answer(again, "/healthz") == 200)  # refused while it restarts
        assert workers_of(again)["http"]["state"] == "running"


pytestmark_mqtt = pytest.mark.skipif(
    __import__("mqtt_broker").missing() is not None,
    reason=__import__("mqtt_broker").missing() or "",
)


@pytestmark_mqtt
def test_a_broken_socket_in_the_outbox_loses_no_event(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    pytest.importorskip("paho.mqtt.client", reason="the monitor's MQTT needs the mqtt extra")
    from mqtt_broker import Broker, Collector
    from thermodepth.sinks.mqtt import PASSWORD_ENV

    broker = Broker()
    broker.start()
    try:
        monkeypatch.setenv(PASSWORD_ENV, broker.password)
        got = Collector(broker, "plant/+/alarms")
        path = monitor_config(
            tmp_path,
            [{"name": "a", "source": "sim", "settings": settings_file(tmp_path).name}],
            http={"listen": None},
            mqtt={"url": broker.url("plant"), "snapshots_hz": 2},
        )
        monitor = Monitor(load_config(path))
        output = monitor.output("mqtt")
        assert output is not None
        monitor.start()
        try:  # the outbox's send: a socket that broke under it
            broken = once(OSError(32, "Broken pipe"), output._send)  # type: ignore[attr-defined]
            monkeypatch.setattr(output, "_send", broken)
            wait_for(lambda: monitor.workers.all["mqtt outbox"].restarts == 1)
            wait_for(lambda: monitor.store.count() >= 5)
            stored = {e["id"] for e in monitor.store.events(5)}
            wait_for(lambda: not stored & {e["id"] for e in monitor.store.outbox(10_000)})
            received = got.until(lambda out: stored <= {m["id"] for _, m, _ in out})
        finally:
            monitor.stop()
        assert {m["rig"] for _, m, _ in received} == {"a"}
        assert monitor.workers.all["mqtt snapshots"].restarts == 0
    finally:
        broker.cleanup()


def test_opcua_serves_again_after_its_loop_dies(tmp_path: Path) -> None:
    pytest.importorskip("asyncua", reason="the OPC UA server needs the opcua extra (asyncua)")
    from asyncua import Client

    from mqtt_broker import free_port

    endpoint = f"opc.tcp://127.0.0.1:{free_port()}/thermodepth"
    path = monitor_config(
        tmp_path,
        [{"name": "a", "source": "sim", "settings": settings_file(tmp_path).name}],
        http={"listen": None},
        opcua={"endpoint": endpoint, "anonymous": True},
    )
    monitor = Monitor(load_config(path))
    monitor.start()

    async def health() -> str:
        async with Client(endpoint, timeout=30) as client:
            ns = await client.get_namespace_index("urn:thermodepth:monitor")
            return str(await client.get_node(f"ns={ns};s=a.Health").read_value())

    try:
        assert asyncio.run(health()) in ("ok", "stale", "fault")
        output = monitor.output("opcua")
        loop = output.loop  # type: ignore[union-attr]
        loop.call_soon_threadsafe(loop.stop)  # its event loop ends under it
        wait_for(lambda: monitor.workers.all["opcua"].restarts == 1)
        wait_for(lambda: output.loop is not None and output.loop is not loop)  # type: ignore[union-attr]
        assert wait_for(lambda: asyncio.run(health()) == "ok")
    finally:
        monitor.stop()
