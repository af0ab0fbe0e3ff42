"""The always-on monitor on the simulated rig, misbehaving when told: every fault detected,
reopened and counted, the healthy rig unaffected, every event in the store with a clip that
replays, and health, events and acknowledgements over HTTP (read by httpx and by
prometheus_client's own parser)."""

from __future__ import annotations

import json
import math
import re
import sqlite3
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

pytest.importorskip("starlette", reason="the monitor needs the monitor extra (starlette)")
pytest.importorskip("uvicorn", reason="the monitor needs the monitor extra (uvicorn)")
pytest.importorskip("prometheus_client", reason="the monitor needs the monitor extra")

import httpx
from prometheus_client.parser import text_string_to_metric_families

from monitor_helpers import (
    FLAPPING,
    PAPER_MODEL,
    log_lines,
    monitor_config,
    settings_file,
    wait_for,
)
from thermodepth.monitor import Monitor, load_config, service
from thermodepth.monitor.http import WEB
from thermodepth.monitor.store import EventStore
from thermodepth.pipeline import Pipeline, Settings
from thermodepth.sources import open_source
from thermodepth.sources.sim import sim_device

# each fault lasts long enough for a rig on a slow, busy machine to see several frames of it;
# unplugged for 3 s, a's frames stop for longer than its stall_s (2 s) by more than the clock's
# tick and the backoff of its reopening
SLOW = "sim:faults=unplug@1s+3s,stall@7s,corrupt@11s+3s"
ODD = "sim:faults=ffc-storm@2s+4s,vox-ramp@4s"
PRE_S = 1.0  # monitor_helpers' storage: pre_s


class Seen:
    """What a run of the monitor showed while it ran and after."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.http: dict[str, Any] = {}


def everything_happened(monitor: Monitor, t0: float) -> bool:
    """Every fault the rigs were told to have came and (but the VOx drift) went, and enough
    alarms with their clips were recorded: however slowly the machine ran them."""
    stored = monitor.store.events(100_000)

    def got(rig: str, event: str, fault: str) -> int:
        return sum(e["rig"] == rig and e["event"] == event and e.get("fault") == fault
                   for e in stored)  # fmt: skip

    raised = [e for e in stored if e["rig"] in "ab" and e["event"] in ("alarm", "escalated")
              and e["rule"] != "sensor_fault"]  # fmt: skip
    late_clips = {e["clip"] for e in raised if e["rig"] == "b" and e["time_s"] - t0 > 3.0}
    return (
        got("a", "clear", "no_data") >= 2
        and got("a", "clear", "corrupt") >= 1
        and got("c", "clear", "shutter") >= 1
        and got("c", "alarm", "vox_range") >= 1
        and len(raised) >= 10
        and len({e["clip"] for e in raised}) >= 4
        and bool(late_clips)
        and monitor.runners["a"].status.stalls >= 1
    )


@pytest.fixture(scope="module")
def seen(tmp_path_factory: pytest.TempPathFactory) -> Seen:
    """Three simulated rigs until everything they were told to do has happened: ``a``
    unplugged, stalled and corrupt, ``b`` healthy, ``c`` with a shutter storm and its sensor
    drifting out of its model's range."""
    folder = tmp_path_factory.mktemp("monitor")
    flapping = settings_file(folder)
    paper = settings_file(folder, PAPER_MODEL, "paper.yaml")
    path = monitor_config(
        folder,
        [
            {"name": "a", "source": SLOW, "settings": flapping.name, "stall_s": 2.0},
            # b's stall_s long: on a busy machine a slow disk or a starved process may hold
            # its frames for seconds; a no_data fault then would be the machine's, not b's
            {
                "name": "b",
                "source": "sim",
                "settings": flapping.name,
                "location": "bay 2",
                "stall_s": 10.0,
            },
            {"name": "c", "source": ODD, "settings": paper.name},
        ],
        failsafe={
            "shutter_window_s": 2,
            "corrupt_s": 0.5,
            "clear_s": 0.5,
            "vox_margin_c": 0,
        },
    )
    out = Seen()
    out.folder = folder  # type: ignore[attr-defined]
    # numba compiles the simulator and the pipeline first (as a live rig would, its first
    # pairs would come late and be dropped): once, before the clock starts
    with open_source("sim", frames=2) as warm:
        pipe = Pipeline(Settings.load(paper), warm.calibration)
        for pair in warm:
            assert pipe.process(pair).on_depth is not None
    with log_lines() as out.lines:
        monitor = Monitor(load_config(path))
        out.t0 = time.time()  # type: ignore[attr-defined]
        monitor.start()
        try:
            client = httpx.Client(base_url=monitor.http.url, timeout=30)
            out.http["healthy"] = wait_for(
                lambda: (r := client.get("/healthz")).status_code == 200 and r.json()
            )
            # a is unplugged from 1 s to 4 s: stale once its stall_s has passed
            out.http["unplugged"] = wait_for(
                lambda: (r := client.get("/healthz")).status_code == 503 and r.json()
            )
            wait_for(lambda: "latched" in str(client.get("/api/status").json()))
            csrf = {"X-CSRF-Token": client.get("/api/session").json()["csrf"]}
            out.http["ack_forged"] = client.post(
                "/api/ack", json={"rig": "b", "rule": "latched", "by": "mallory"}
            )
            out.http["ack_form"] = client.post(
                "/api/ack", content='{"rig": "b", "rule": "latched", "by": "mallory"}',
                headers={**csrf, "Content-Type": "text/plain"},
            )  # fmt: skip
            out.http["ack_unknown_rig"] = client.post(
                "/api/ack", json={"rig": "z", "rule": "latched", "by": "jane"}, headers=csrf
            )
            out.http["ack_unknown_rule"] = client.post(
                "/api/ack", json={"rig": "b", "rule": "melt", "by": "jane"}, headers=csrf
            )
            out.http["ack_bad"] = client.post(
                "/api/ack", json={"rig": "b", "rule": "latched"}, headers=csrf
            )
            out.http["ack"] = client.post(
                "/api/ack", json={"rig": "b", "rule": "latched", "by": "operator jane"},
                headers=csrf,
            )  # fmt: skip
            wait_for(lambda: everything_happened(monitor, out.t0), every_s=0.5)  # type: ignore[attr-defined]
            out.http["status"] = client.get("/api/status").json()
            out.http["events"] = client.get("/api/events", params={"limit": 1000}).json()
            out.http["page"] = client.get("/api/events", params={"limit": 5, "rig": "a"}).json()
            out.http["metrics"] = client.get("/metrics").text
            out.http["bad_limit"] = client.get("/api/events", params={"limit": "x"})
            client.close()
        finally:
            monitor.stop()
    out.status = monitor.status()  # type: ignore[attr-defined]
    out.device_t0_unix = {  # type: ignore[attr-defined]
        name: sim_device(r.spec).t0_unix for name, r in monitor.runners.items()
    }
    out.store = EventStore(folder / "store" / "events.sqlite")  # type: ignore[attr-defined]
    return out


def events_of(seen: Seen, rig: str, rule: str | None = None) -> list[dict[str, Any]]:
    rows = seen.store.events(10_000, rig)  # type: ignore[attr-defined]
    return [e for e in reversed(rows) if rule is None or e["rule"] == rule]


def faults(seen: Seen, rig: str) -> list[tuple[str, str]]:
    return [(e["event"], e["fault"]) for e in events_of(seen, rig, "sensor_fault")]


def rig_status(seen: Seen, rig: str) -> dict[str, Any]:
    return next(r for r in seen.status["rigs"] if r["name"] == rig)  # type: ignore[attr-defined]


def test_unplug_and_stall_are_reopened_counted_and_fail_safe(seen: Seen) -> None:
    # (a machine starved of CPU may add stalls of its own: at least these)
    a = rig_status(seen, "a")
    assert a["stalls"] >= 1  # the stall at 4 s, seen by the monitor's clock
    assert a["reconnects"] >= 2  # after the unplugging and after the stall
    assert a["seconds_without_data"] > 0.5
    got = faults(seen, "a")
    # unplugged and stalled: no data, each raised and cleared when frames came back
    raised, cleared = got.count(("alarm", "no_data")), got.count(("clear", "no_data"))
    assert raised >= 2 and cleared >= 2 and raised - cleared in (0, 1)
    assert [e for e, _ in got if _ == "no_data"][:4] == ["alarm", "clear", "alarm", "clear"]
    assert any("device lost: sim: unplugged at 1 s" in line for line in seen.lines)
    assert any(line.startswith("a: stalled (no new frame for 2.") for line in seen.lines)
    assert a["frames"] > 20


def test_corrupt_frames_raise_and_clear_a_sensor_fault(seen: Seen) -> None:
    got = faults(seen, "a")
    assert ("alarm", "corrupt") in got and ("clear", "corrupt") in got
    raised = next(e for e in events_of(seen, "a", "sensor_fault") if e["fault"] == "corrupt")
    assert "of the frame's pixels cannot be values of their kind" in raised["condition"]
    # on a frame of the simulated device's corrupt seconds (11-14 s of its own clock)
    assert 11.0 <= float(raised["time_s"]) - seen.device_t0_unix["a"] < 14.0  # type: ignore[attr-defined]


def test_shutter_storm_and_vox_drift_raise_sensor_faults(seen: Seen) -> None:
    got = faults(seen, "c")
    assert ("alarm", "shutter") in got and ("clear", "shutter") in got
    vox = [e for e in events_of(seen, "c", "sensor_fault") if e["fault"] == "vox_range"]
    assert [e["event"] for e in vox] == ["alarm"]  # drifting on: still raised at the end
    assert "outside the fitted 25-40 C" in vox[0]["condition"]
    assert vox[0]["vox_temp_c"] is None or vox[0]["vox_temp_c"] > 40  # 1 K/s from 35 C at 4 s
    assert {"rule": "sensor_fault", "level": "alarm", "fault": "vox_range"} in rig_status(
        seen, "c"
    )["active_alarms"]


def test_the_healthy_rig_is_unaffected(seen: Seen) -> None:
    # while a and c misbehaved, b had no fault, was never reopened, stalled or without data
    # (a machine short of CPU may make it drop pairs to keep its pace: that is allowed)
    b = rig_status(seen, "b")
    assert faults(seen, "b") == []
    assert b["reconnects"] == 0 and b["stalls"] == 0 and b["seconds_without_data"] == 0
    assert b["frames"] > 20 and b["last_error"] is None
    assert not [line for line in seen.lines if line.startswith("b: ") and "reopening" in line]


def test_every_event_is_stored_and_every_alarm_has_a_clip_that_replays(seen: Seen) -> None:
    counts = seen.status["event_counts"]  # type: ignore[attr-defined]
    stored = seen.store.events(100_000)  # type: ignore[attr-defined]
    assert len(stored) == sum(n for rig in counts.values() for n in rig.values())
    raised = [e for e in stored if e["event"] in ("alarm", "escalated") and e["rig"] in "ab"]
    raised = [e for e in raised if e["rule"] != "sensor_fault"]
    assert len(raised) >= 10
    assert all(e.get("clip") for e in raised)
    clips = {e["clip"] for e in raised}
    assert len(clips) >= 4  # clips end after clip_max_s: 3 s
    root = seen.folder / "store" / "clips"  # type: ignore[attr-defined]
    for clip in clips:
        folder = root / clip
        assert (folder / "overlay.png").stat().st_size > 10_000
        assert (folder / "frame.ply").read_bytes().startswith(b"ply\n")
        with open_source(f"recording:{folder / 'clip.zarr'}") as src:
            pairs = list(src)
        times = np.array([p.thermal_time_s for p in pairs])
        assert np.all(np.diff(times) > 0)
        for e in (e for e in raised if e["clip"] == clip):
            assert e["frame"] in {p.index for p in pairs}  # the frame that raised it
            assert times[0] - 1e-4 <= e["time_s"] <= times[-1] + 1e-4  # times to 0.1 ms


def test_a_clip_holds_the_seconds_before_its_first_event(seen: Seen) -> None:
    by_clip: dict[str, list[float]] = {}
    for e in events_of(seen, "b"):
        if e.get("clip"):
            by_clip.setdefault(e["clip"], []).append(e["time_s"])
    # clips begun after the first seconds, when the pre-trigger buffer is full
    late = [(c, t) for c, t in by_clip.items() if min(t) - seen.t0 > 3.0]  # type: ignore[attr-defined]
    bounded = 0
    for clip, times_s in late:
        path = seen.folder / "store" / "clips" / clip / "clip.zarr"  # type: ignore[attr-defined]
        with open_source(f"recording:{path}") as src:
            frames_s = np.array([p.thermal_time_s for p in src])
        before_s = min(times_s) - frames_s[0]
        assert before_s <= PRE_S + 1e-3  # pre_s before it, never more
        assert frames_s[-1] - max(times_s) <= 1.0 + 1e-3  # post_s
        # the pairs it had before the event (how many: as many as a busy machine left it;
        # the buffer's own bounds are test_monitor_parts')
        bounded += int(np.count_nonzero(frames_s < min(times_s) - 1e-4) >= 1)
    assert bounded >= 1


def test_healthz_says_which_rig_is_stale(seen: Seen) -> None:
    assert seen.http["healthy"] == {"status": "ok"}
    assert seen.http["unplugged"] == {"status": "stale", "rigs": ["a"], "workers": []}


def test_acknowledge_over_http(seen: Seen) -> None:
    # without the page's CSRF token, or as a form a foreign page could post: refused
    assert seen.http["ack_forged"].status_code == 403
    assert "X-CSRF-Token" in seen.http["ack_forged"].json()["error"]
    assert seen.http["ack_form"].status_code == 403
    assert seen.http["ack_unknown_rig"].status_code == 404
    assert seen.http["ack_unknown_rule"].status_code == 404
    assert seen.http["ack_unknown_rule"].json() == {"error": "b: no alarm rule 'melt'"}
    assert seen.http["ack_bad"].status_code == 400
    ack = seen.http["ack"]
    assert ack.status_code == 200
    (event,) = ack.json()
    assert event["event"] == "acknowledged" and event["by"] == "operator jane"
    stored = [e for e in events_of(seen, "b", "latched")]
    assert [e["event"] for e in stored] == ["alarm", "acknowledged"]  # latched: still hot
    assert stored[1]["by"] == "operator jane" and stored[1]["at_utc"].endswith("+00:00")


def test_status_and_events_over_http(seen: Seen) -> None:
    status = seen.http["status"]
    assert [r["name"] for r in status["rigs"]] == ["a", "b", "c"]
    b = status["rigs"][1]
    assert b["location"] == "bay 2" and b["up"] == 1 and b["vox_temp_c"] == 35.0
    assert b["pipeline_ms"]["median"] > 0 and 0 <= b["last_frame_age_s"] < 3.0  # its stall_s
    assert status["storage"]["event_store_bytes"] > 0
    events = seen.http["events"]
    ids = [e["id"] for e in events]
    assert ids == sorted(ids, reverse=True)  # newest first
    assert {"rig", "rule", "level", "state", "time_s", "time_utc"} <= set(events[0])
    assert {e["state"] for e in events} >= {"alarm", "clear", "acknowledged"}, events[:3]
    page = seen.http["page"]
    assert len(page) == 5 and {e["rig"] for e in page} == {"a"}
    assert seen.http["bad_limit"].status_code == 400


def test_metrics_read_by_prometheus_own_parser(seen: Seen) -> None:
    samples = [s for f in text_string_to_metric_families(seen.http["metrics"]) for s in f.samples]

    def value(name: str, **labels: str) -> float:
        return next(s.value for s in samples if s.name == name and s.labels == labels)

    assert value("thermodepth_rig_stalls_total", rig="a") >= 1
    assert value("thermodepth_rig_reconnects_total", rig="b") == 0
    assert value("thermodepth_rig_up", rig="b") == 1
    frames = value("thermodepth_rig_frames_total", rig="b")
    assert 20 < frames <= rig_status(seen, "b")["frames"]  # read before the end
    assert value("thermodepth_rig_alarms_active", rig="c", level="alarm") >= 1
    assert value("thermodepth_events_total", rig="a", state="alarm") >= 3
    assert value("thermodepth_event_store_bytes") > 0
    row = value("thermodepth_alarm_latency_seconds", to="event_row", quantile="0.5")
    assert row > 0 and math.isfinite(row)  # how fast is bench_monitor's to say
    workers = {s.labels["worker"]: s.value for s in samples
               if s.name == "thermodepth_worker_up"}  # fmt: skip
    assert set(workers) >= {"clock", "storage", "evidence pictures", "http"}
    assert all(v == 1 for v in workers.values())


def concrete(path: str) -> str:
    """A route's path with its parameters filled in."""
    fill = {"id": "1", "what": "snapshot.png", "rig": "t"}
    return re.sub(r"\{(\w+)(:\w+)?\}", lambda m: fill.get(m.group(1), "x"), path)


def test_every_route_but_the_public_ones_wants_the_token(tmp_path: Path) -> None:
    from starlette.routing import Mount, Route

    from thermodepth.monitor.http import PUBLIC

    (tmp_path / "token").write_text("s3cret\n", encoding="utf-8")
    path = monitor_config(
        tmp_path,
        [{"name": "t", "source": "sim", "settings": settings_file(tmp_path).name}],
        http={"token_file": "token"},
    )
    monitor = Monitor(load_config(path))
    monitor.start()
    try:
        asked = []
        for route in monitor.http.app.routes:  # the app's own table: a new route is walked too
            if isinstance(route, Mount):
                asked += [("GET", f"{route.path}/{f.name}") for f in WEB.iterdir()]
            else:
                assert isinstance(route, Route)
                methods = sorted((route.methods or {"GET"}) - {"HEAD"})
                asked += [(m, concrete(route.path)) for m in methods]
        assert {p for _, p in asked} >= {"/api/openapi.json", "/metrics", "/static/app.js"}
        with httpx.Client(base_url=monitor.http.url, timeout=30) as client:
            for method, where in asked:
                got = client.request(method, where)
                if where in PUBLIC:
                    assert got.status_code != 401, where
                else:
                    assert got.status_code == 401, (method, where, got.status_code)
            none = client.get("/api/openapi.json")
            assert none.json() == {"error": "a token is needed"}
            assert none.headers["www-authenticate"] == 'Bearer realm="thermodepth"'
            wrong = client.get("/api/events", headers={"Authorization": "Bearer nope"})
            assert wrong.status_code == 401 and wrong.json() == {"error": "wrong token"}
            assert 'error="invalid_token"' in wrong.headers["www-authenticate"]
            ended = client.get("/api/status", cookies={"thermodepth_session": "gone"})
            assert "log in again" in ended.json()["error"]
            page = client.get("/rig/t", headers={"Accept": "text/html"})
            assert page.status_code == 401 and 'url=/login?next=/rig/t"' in page.text
            right = {"Authorization": "Bearer s3cret"}
            assert client.get("/api/status", headers=right).status_code == 200
            schema = client.get("/api/openapi.json", headers=right).json()
            assert "/api/status" in schema["paths"]
    finally:
        monitor.stop()


def test_events_the_store_cannot_take_are_kept_published_and_written_later(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    path = monitor_config(
        tmp_path, [{"name": "t", "source": "sim", "settings": settings_file(tmp_path).name}]
    )
    monitor = Monitor(load_config(path))
    real_add = monitor.store.add

    def full(event: dict[str, Any], outbox: bool = False) -> int:
        raise sqlite3.OperationalError("database or disk is full")

    monitor.start()
    try:
        wait_for(lambda: monitor.store.count() >= 2)
        monkeypatch.setattr(monitor.store, "add", full)
        wait_for(lambda: len(monitor.backlog) >= 4)
        with httpx.Client(base_url=monitor.http.url, timeout=5) as client:
            shown = client.get("/api/events").json()
        waiting = [e for e in shown if "id" not in e]
        assert len(waiting) >= 4 and shown[: len(waiting)] == waiting  # told first
        fault = next(e for e in waiting if e["rule"] == "storage_fault")
        assert fault["event"] == "alarm" and fault["rig"] == "monitor"
        assert fault["condition"].startswith("event t ")
        assert fault["condition"].endswith(
            "(database or disk is full): kept in memory until it can be"
        )
        assert monitor.status()["storage"]["fault"] is True
        monkeypatch.setattr(monitor.store, "add", real_add)  # space again
        monitor.sweep()  # written, in order ...
        assert monitor.backlog == []
        monitor.sweep()  # ... and a sweep with nothing new to tell clears the fault
        stored = monitor.store.events(1000)
        assert {"alarm", "clear"} <= {e["event"] for e in stored if e["rule"] == "storage_fault"}
        assert monitor._captured == {}  # no output delivers: no capture time kept for one
        monkeypatch.setattr(monitor.store, "add", full)
        wait_for(lambda: monitor.backlog)
        monkeypatch.setattr(service, "BACKLOG_MAX", 2)  # bounded: the oldest dropped, counted
        lost = wait_for(lambda: monitor.status()["storage"]["events_lost"])
        assert len(monitor.backlog) == 2 and lost >= 1
    finally:
        monitor.stop()  # a disk still full: the log keeps what could not be written
    lines = [r.getMessage() for r in caplog.records if r.name == "thermodepth.monitor"]
    at = next(i for i, line in enumerate(lines) if "events could not be written to" in line)
    assert all(json.loads(line)["rig"] in ("t", "monitor") for line in lines[at + 1 :])
    assert len(lines) > at + 1


def test_a_reload_that_adds_a_rule_keeps_the_raised_ones(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    settings = settings_file(tmp_path)
    path = monitor_config(
        tmp_path, [{"name": "a", "source": "sim", "settings": settings.name}], http={"listen": None}
    )
    monitor = Monitor(load_config(path))
    monitor.start()

    def latched() -> list[dict[str, Any]]:
        return [e for e in monitor.store.events(10_000, "a") if e["rule"] == "latched"]

    try:
        wait_for(lambda: [e["event"] for e in latched()] == ["alarm"])
        monitor.acknowledge("a", "latched", "jane")
        before = latched()
        settings.write_text(FLAPPING + "  - {name: warm, above_c: 50, level: warning}\n")
        monitor.reload(load_config(path))
        runner = monitor.runners["a"]
        wait_for(lambda: any(e["rule"] == "warm" for e in monitor.store.events(100, "a")))
        frames = runner.status.frames
        wait_for(lambda: runner.status.frames > frames + 5)  # the rig went on after it
        assert latched() == before  # not raised again: no second alarm, no new clip
        kept = next(a for a in runner.raised() if a["rule"] == "latched")
        assert kept["acknowledged"]["by"] == "jane"
    finally:
        monitor.stop()
    assert "a: started (reload); rules kept as they were: hot, latched" in caplog.messages
