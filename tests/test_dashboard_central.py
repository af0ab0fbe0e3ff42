"""One screen for many monitors (``thermodepth dashboard``): what arrives on the broker, as
the monitors publish it, becomes rigs, readings, active alarms, events (each once) with their
snapshots, live pictures and trends; and, on a real Mosquitto, two monitors of one rig each
and one central dashboard: both rigs on its API, their pictures, an alarm acknowledged
through it into the rig's own monitor, a stopped monitor's rig stale."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

pytest.importorskip("starlette", reason="the dashboard needs the monitor extra (starlette)")
pytest.importorskip("paho.mqtt.client", reason="the dashboard's MQTT needs the mqtt extra")

import httpx

import browser
import mqtt_broker
from monitor_helpers import monitor_config, settings_file, wait_for
from thermodepth.app.monitor import run_dashboard
from thermodepth.errors import InputError
from thermodepth.monitor import Monitor, load_config
from thermodepth.monitor.central import CentralDashboard, monitor_of, split_topic
from thermodepth.monitor.config import HttpConfig
from thermodepth.monitor.http import HttpServer
from thermodepth.monitor.supervisor import AckRefusedError
from thermodepth.pipeline import MqttSettings
from thermodepth.sinks.mqtt import PASSWORD_ENV


def jpeg(width: int, height: int, value: int) -> bytes:
    ok, data = cv2.imencode(".jpg", np.full((height, width, 3), value, np.uint8))
    assert ok
    return bytes(data)


def ok(response: httpx.Response) -> httpx.Response | None:
    return response if response.status_code == 200 else None


def test_topics_name_rigs_by_their_path_under_the_prefix() -> None:
    assert split_topic("plant", "plant/edge1/line3/status") == ("edge1/line3", "status")
    assert split_topic("plant", "plant/line3/ack/result") == ("line3", "ack/result")
    assert split_topic("plant", "plant/a/snapshot/overlay.jpg") == ("a", "snapshot/overlay.jpg")
    assert split_topic("plant", "plant/a/ack") is None  # our own command, not an answer
    assert split_topic("plant", "other/a/status") is None
    assert split_topic("plant", "plant/status") is None
    assert monitor_of("edge1/line3") == "edge1/monitor" and monitor_of("line3") == "monitor"


def test_what_arrives_becomes_rigs_alarms_events_and_pictures(tmp_path: Path) -> None:
    central = CentralDashboard("mqtt://127.0.0.1:1/plant", tmp_path, MqttSettings())
    say = lambda topic, body: central._message(  # noqa: E731
        f"plant/{topic}", body if isinstance(body, bytes) else json.dumps(body).encode()
    )
    say("edge1/monitor/status", {"state": "running", "rigs": ["a"]})
    status = {"name": "a", "health": "ok", "state": "running", "active_alarms": [],
              "hottest": None, "rois": {}, "fps": 8.7}  # fmt: skip
    say("edge1/a/status", status)
    say("edge1/a/measurements", {
        "frame": 7, "time_s": 1.0e9, "vox_temp_c": 31.0,
        "hottest": {"max_c": 67.5, "position_m": [0, 0, 1], "distance_m": 1.0, "resolvable": True},
        "rois": {"plate": {"max_c": 67.5, "mean_c": 40.0, "min_c": 25.0, "n": 100}},
    })  # fmt: skip
    raised = {"id": 41, "rig": "a", "rule": "hot", "level": "alarm", "event": "alarm",
              "time_utc": "2026-11-26T18:00:00+00:00", "value_c": 67.5, "clip": "c1"}  # fmt: skip
    say("edge1/a/alarms", raised)
    say("edge1/a/alarms", raised)  # delivered again (at least once): kept once
    say("edge1/a/alarms", b"{not json")  # one line, nothing kept
    (rig,) = central.status()["rigs"]
    assert rig["name"] == "edge1/a" and rig["monitor"] == "edge1/monitor"
    assert rig["hottest"]["max_c"] == 67.5 and rig["rois"]["plate"]["mean_c"] == 40.0
    assert rig["active_alarms"] == [{"rule": "hot", "level": "alarm"}]
    (event,) = central.events()
    assert event["rig"] == "edge1/a" and event["origin"] == "edge1/a#41"
    assert central.evidence_of(event) == []  # no overlay had come yet ...
    say("edge1/a/snapshot/overlay.jpg", jpeg(640, 360, 200))
    assert central.evidence_of(event) == ["snapshot.png"]  # ... the first one is its snapshot
    png = cv2.imread(str(central.evidence_file(event["id"], "snapshot.png")))
    assert png.shape == (360, 640, 3) and abs(int(png.mean()) - 200) <= 2
    assert central.evidence_file(event["id"], "clip.zip") is None  # on the monitor's disk
    small = cv2.imdecode(
        np.frombuffer(central.picture("edge1/a", "overlay", 320).data, np.uint8), 1
    )
    assert small.shape == (180, 320, 3)
    assert central.picture("edge1/a", "thermal") is None and central.picture("z", "overlay") is None
    assert central.trend("edge1/a") == [
        {"time_s": 1.0e9, "hottest_c": 67.5, "rois": {"plate": 67.5}}
    ]
    say("edge1/a/alarms", {**raised, "id": 42, "event": "acknowledged", "by": "jane",
                           "at_utc": "2026-11-26T18:00:05+00:00"})  # fmt: skip
    assert central.status()["rigs"][0]["active_alarms"][0]["acknowledged"]["by"] == "jane"
    say("edge1/a/alarms", {**raised, "id": 43, "event": "clear"})
    assert central.status()["rigs"][0]["active_alarms"] == []
    assert [e["event"] for e in central.events()] == ["clear", "acknowledged", "alarm"]
    assert central.stale_rigs() == ["edge1/a"]  # the broker is not there
    with pytest.raises(AckRefusedError) as info:
        central.acknowledge("edge9/z", "hot", "jane")
    assert info.value.status == 404
    # a rig's recent list may come before the live copy of an event in it: listed at once,
    # and the live copy still raises it and gives it its snapshot
    later = {**raised, "id": 44, "event": "alarm"}
    say("edge1/a/events/recent", [later])
    assert central.events()[0]["origin"] == "edge1/a#44"
    assert central.status()["rigs"][0]["active_alarms"] == []  # not live: the status says
    say("edge1/a/alarms", later)
    assert central.status()["rigs"][0]["active_alarms"] == [{"rule": "hot", "level": "alarm"}]
    assert central.evidence_of(central.events()[0]) == ["snapshot.png"]
    assert [e["id"] for e in central.events()].count(central.events()[0]["id"]) == 1  # once
    # a retired rig (its status emptied on the broker) goes from every page
    say("edge1/a/status", b"")
    assert central.status()["rigs"] == []
    central.store.close()


def test_the_dashboards_options_are_checked(tmp_path: Path) -> None:
    http = HttpConfig(listen="0.0.0.0:8090", tls_cert=tmp_path / "c.pem")
    with pytest.raises(InputError) as info:
        run_dashboard("mqtt://127.0.0.1/plant", tmp_path, http, MqttSettings())
    assert str(info.value).splitlines() == [
        "--listen: 0.0.0.0:8090 is reachable from other machines: give --token-file (or "
        "THERMODEPTH_HTTP_TOKEN), or listen on 127.0.0.1",
        "--tls-cert and --tls-key go together",
        f"--tls-cert: {tmp_path / 'c.pem'}: no such file",
    ]


LATCHED = """\
hotspots:
  threshold_c: 50
alarms:
  - {name: latched, above_c: 60, for_s: 1, latch: true}
"""


needs_broker = pytest.mark.skipif(
    mqtt_broker.missing() is not None, reason=mqtt_broker.missing() or ""
)


@pytest.fixture(scope="module")
def plant(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """A broker; two monitors of one paced simulated rig each, publishing under plant/edge1
    and plant/edge2; a central dashboard of plant/ with a token, served on loopback."""
    tmp_path = tmp_path_factory.mktemp("plant")
    broker = mqtt_broker.Broker()
    broker.start()
    mp = pytest.MonkeyPatch()
    mp.setenv(PASSWORD_ENV, broker.password)
    monitors: dict[str, Monitor] = {}
    central = server = None
    try:
        for edge, rig in (("edge1", "a"), ("edge2", "b")):
            folder = tmp_path / edge
            folder.mkdir()
            settings_file(folder, LATCHED)
            path = monitor_config(
                folder,
                [{"name": rig, "source": "sim:pace=real", "settings": "s.yaml"}],
                http={"listen": None},
                mqtt={"url": broker.url(f"plant/{edge}"), "connect_timeout_s": 2,
                      "snapshots_hz": 2, "client_id": f"monitor-{edge}"},
            )  # fmt: skip
            monitors[edge] = Monitor(load_config(path))
            monitors[edge].start()
        (tmp_path / "token").write_text("s3cret\n")
        central = CentralDashboard(broker.url("plant"), tmp_path / "central", MqttSettings())
        central.start()
        server = HttpServer(
            central, HttpConfig(listen="127.0.0.1:0", token_file=tmp_path / "token")
        )
        server.start()
        yield monitors, server, broker, tmp_path
    finally:
        for m in monitors.values():
            m.stop()
        if server is not None:
            server.stop()
        if central is not None:
            central.stop()
        mp.undo()
        broker.cleanup()


def plant_broker(plant: Any) -> mqtt_broker.Broker:
    return plant[2]


def server_broker(plant: Any) -> str:
    return str(plant[2].url("plant"))


def server_folder(plant: Any) -> Path:
    return Path(plant[3])


def bearer(server: HttpServer) -> httpx.Client:
    return httpx.Client(base_url=server.url, timeout=10, headers={"Authorization": "Bearer s3cret"})


@needs_broker
def test_two_monitors_and_one_central_dashboard_on_one_broker(plant: Any) -> None:
    monitors, server, *_ = plant
    with bearer(server) as c:

        def rigs() -> dict[str, Any]:
            found = {r["name"]: r for r in c.get("/api/status").json()["rigs"]}
            ready = all(r["hottest"] and r["health"] == "ok" for r in found.values())
            return found if len(found) == 2 and ready else {}

        found = wait_for(rigs)  # both measuring (a busy machine may start one late)
        assert sorted(found) == ["edge1/a", "edge2/b"]
        assert all(60 < r["hottest"]["max_c"] < 75 for r in found.values())
        overlay = wait_for(lambda: ok(c.get("/api/rigs/edge1/a/overlay.jpg?width=320")))
        assert overlay.headers["content-type"] == "image/jpeg"
        img = cv2.imdecode(np.frombuffer(overlay.content, np.uint8), 1)
        assert img.shape[1] == 320
        thermal = wait_for(lambda: ok(c.get("/api/rigs/edge2%2Fb/thermal.png")))
        assert thermal.content.startswith(b"\x89PNG")
        assert c.get("/rig/edge2%2Fb").status_code == 200  # the rig's page, by its path

        # the alarm raised on edge1, acknowledged through the central dashboard
        def raised() -> list[dict[str, Any]]:
            return [e for e in c.get("/api/events?rig=edge1/a").json()
                    if e["rule"] == "latched" and e["event"] == "alarm"]  # fmt: skip

        event = wait_for(raised)[0]
        wait_for(lambda: c.get(f"/api/events/{event['id']}").json()["evidence"])
        assert c.get(f"/api/events/{event['id']}/snapshot.png").content.startswith(b"\x89PNG")
        assert c.get(f"/api/events/{event['id']}/clip.zip").status_code == 404
        ack = c.post("/api/ack", json={"rig": "edge1/a", "rule": "latched", "by": "jane"})
        assert ack.status_code == 200 and ack.json()[0]["event"] == "acknowledged"
        edge1 = monitors["edge1"].store.events(50)
        assert [(e["rig"], e["by"]) for e in edge1 if e["event"] == "acknowledged"] == [
            ("a", "jane")
        ]
        wait_for(lambda: c.get("/api/events?state=acknowledged").json())
        refused = c.post("/api/ack", json={"rig": "edge2/b", "rule": "melt", "by": "jane"})
        assert refused.status_code == 409 and "melt" in refused.json()["error"]
        unknown = c.post("/api/ack", json={"rig": "b", "rule": "latched", "by": "j"})
        assert unknown.status_code == 404


@needs_broker
@pytest.mark.skipif(browser.missing() is not None, reason=browser.missing() or "")
def test_the_central_dashboards_pages_in_a_browser(plant: Any) -> None:
    from selenium.webdriver.common.by import By

    _, server, *_ = plant
    driver = browser.chromium()
    try:
        driver.get(f"{server.url}/login")
        browser.fill_login(driver, "s3cret")
        script = "return [...document.querySelectorAll('section.card')].map((c) => c.dataset.rig)"
        assert wait_for(lambda: driver.execute_script(script) == ["edge1/a", "edge2/b"])
        loaded = (
            "const i = document.querySelector('section.card[data-rig=\"edge2/b\"] img');"
            "return i && i.complete ? i.naturalWidth : 0"
        )
        assert wait_for(lambda: driver.execute_script(loaded)) == 640
        driver.find_element(By.LINK_TEXT, "edge2/b").click()  # the rig's page, by its path
        wait_for(
            lambda: driver.execute_script("return document.title") == "thermodepth · edge2/b", 5
        )
    finally:
        driver.quit()


@needs_broker
def test_a_late_dashboard_lists_the_events_behind_the_alarms_it_shows(plant: Any) -> None:
    monitors, server, *_ = plant
    broker_url = server_broker(plant)
    with bearer(server) as c:  # the plant's own dashboard has seen edge1's alarm raised
        wait_for(lambda: [e for e in c.get("/api/events?rig=edge1/a").json()
                          if e["rule"] == "latched" and e["event"] == "alarm"])  # fmt: skip
    late = CentralDashboard(
        broker_url, server_folder(plant) / "late", MqttSettings(client_id="late-dashboard")
    )
    late.start()  # started after the alarm: it learns it from what is retained
    try:

        def active() -> set[str]:
            return {a["rule"] for r in late.status()["rigs"] if r["name"] == "edge1/a"
                    for a in r["active_alarms"]}  # fmt: skip

        def listed() -> list[dict[str, Any]]:  # the event, and the alarm state (retained
            # on a topic of its own, so it may come second)
            found = [e for e in late.events(100, rig="edge1/a") if e["rule"] == "latched"]
            return found if "latched" in active() else []

        events = wait_for(listed)
        assert events[-1]["event"] == "alarm"
        edge1 = {e["id"] for e in monitors["edge1"].store.events(100)}
        assert {int(e["origin"].rpartition("#")[2]) for e in events} <= edge1  # theirs, once
    finally:
        late.stop()


@needs_broker
def test_a_stopped_monitors_rig_shows_stopped_and_is_retired(plant: Any) -> None:
    monitors, server, *_ = plant
    with bearer(server) as c:
        wait_for(lambda: len(c.get("/api/status").json()["rigs"]) == 2)
        csrf = {"X-CSRF-Token": "unused"}  # the bearer token needs none
        busy = c.post("/api/retire", json={"name": "edge2"}, headers=csrf)
        assert busy.status_code == 409 and "still running: edge2/b" in busy.json()["error"]
        monitors.pop("edge2").stop()

        def stopped() -> dict[str, Any] | None:
            rigs = {r["name"]: r for r in c.get("/api/status").json()["rigs"]}
            b = rigs.get("edge2/b")
            return b if b and b["state"] == "stopped" else None

        b = wait_for(stopped)  # at once: its monitor said so on its way out
        assert b["up"] == 0 and b["fps"] == 0 and b["health"] == "stopped"
        assert c.get("/healthz").status_code == 200  # stopped on purpose is not stale
        refused = c.post("/api/ack", json={"rig": "edge2/b", "rule": "latched", "by": "jane"})
        assert refused.status_code == 409 and "its monitor has stopped" in refused.json()["error"]
        gone = c.post("/api/retire", json={"name": "edge2"}, headers=csrf)
        assert gone.status_code == 200 and gone.json() == {"retired": ["edge2/b"]}
        assert [r["name"] for r in c.get("/api/status").json()["rigs"]] == ["edge1/a"]
        assert c.post("/api/retire", json={"name": "edge2"}).status_code == 404
    # retired for every dashboard: nothing of edge2 is retained on the broker any more
    retained = mqtt_broker.Collector(plant_broker(plant), "plant/edge2/#", client_id="late")
    assert retained.drain(settle_s=1.0) == []
    retained.close()


@needs_broker
def test_a_dead_monitors_rig_is_stale(plant: Any) -> None:
    import paho.mqtt.client as mqtt

    _, server, *_ = plant
    with bearer(server) as c:
        wait_for(lambda: any(r["name"] == "edge1/a" and r["up"]
                             for r in c.get("/api/status").json()["rigs"]))  # fmt: skip
        # what the broker says for a monitor killed: its last will
        will = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="will")
        will.username_pw_set("rig", plant_broker(plant).password)
        will.connect("127.0.0.1", plant_broker(plant).port)
        will.loop_start()
        will.publish("plant/edge1/monitor/status", '{"state": "died"}', 1, True).wait_for_publish()
        will.disconnect()
        will.loop_stop()
        sick = wait_for(lambda: (r := c.get("/healthz")).status_code == 503 and r.json())
        assert sick["rigs"] == ["edge1/a"]
