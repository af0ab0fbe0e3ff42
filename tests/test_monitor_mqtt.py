"""The monitor on a real Mosquitto broker started by the tests (skipped, naming the package,
where it is not installed): each rig under its prefix, no event lost while the broker is away
or across a restart of the monitor (the outbox on disk), acknowledgements by MQTT."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("paho.mqtt.client", reason="the monitor's MQTT needs the mqtt extra")

import paho.mqtt.client as mqtt

from monitor_helpers import FLAPPING, PATIENCE_S, monitor_config, settings_file, wait_for
from mqtt_broker import Broker, Collector, missing
from thermodepth.errors import InputError
from thermodepth.monitor import Monitor, load_config
from thermodepth.monitor.store import EventStore
from thermodepth.sinks.mqtt import PASSWORD_ENV

pytestmark = pytest.mark.skipif(missing() is not None, reason=missing() or "")


@pytest.fixture()
def broker() -> Any:
    b = Broker(persistence=True)  # keeps the collector's session across its own restart
    try:
        b.start()
        yield b
    finally:
        b.cleanup()


def start_monitor(folder: Path, broker: Broker, rigs: list[dict[str, Any]]) -> Monitor:
    settings = settings_file(folder)
    for rig in rigs:
        rig.setdefault("settings", settings.name)
    path = monitor_config(
        folder,
        rigs,
        http={"listen": None},
        mqtt={"url": broker.url("plant"), "measurements_hz": 5, "connect_timeout_s": 2},
    )
    monitor = Monitor(load_config(path))
    monitor.start()
    return monitor


def outbox_ids(monitor: Monitor) -> set[int]:
    return {e["id"] for e in monitor.store.outbox(100_000)}


def alarms(received: list[tuple[str, Any, bool]], rig: str) -> list[dict[str, Any]]:
    return [m for t, m, _ in received if t == f"plant/{rig}/alarms"]


def command(broker: Broker, topic: str, payload: str) -> dict[str, Any]:
    """Publish ``payload`` to ``topic`` and return the answer on ``topic/result``."""
    answers = Collector(broker, f"{topic}/result", client_id=f"ack-{time.monotonic_ns()}")
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="operator")
    c.username_pw_set("rig", broker.password)
    c.connect("127.0.0.1", broker.port)
    c.loop_start()
    c.publish(topic, payload, qos=1).wait_for_publish(PATIENCE_S)
    got = answers.messages.get(timeout=PATIENCE_S)
    c.disconnect()
    c.loop_stop()
    answers.close()
    return dict(got[1])


def test_each_rig_under_its_prefix_nothing_lost_while_the_broker_is_away(
    broker: Broker, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(PASSWORD_ENV, broker.password)
    got = Collector(broker, "plant/#")
    monitor = start_monitor(tmp_path, broker, [{"name": "a", "source": "sim"},
                                               {"name": "b", "source": "sim"}])  # fmt: skip
    try:
        wait_for(lambda: {e["rig"] for e in monitor.store.events(100)} == {"a", "b"})
        broker.stop()
        before = {e["id"] for e in monitor.store.events(100_000)}
        # alarms go on, into the outbox: kept on disk until the broker is back
        wait_for(lambda: len(outbox_ids(monitor) - before) >= 10)
        during = outbox_ids(monitor) - before
        broker.start()
        wait_for(lambda: monitor.output("mqtt").connection.connected)  # type: ignore[union-attr]
        wait_for(got.client.is_connected)
        bad = command(broker, "plant/b/ack", '{"rule": "latched"}')
        unknown = command(broker, "plant/b/ack", '{"rule": "melt", "by": "jane"}')
        ack = command(broker, "plant/b/ack", '{"rule": "latched", "by": "operator jane"}')
        wait_for(lambda: not outbox_ids(monitor) & during)  # what waited has gone out
    finally:
        monitor.stop()
    received = got.drain(settle_s=1.0)
    got.close()
    store = EventStore(tmp_path / "store" / "events.sqlite")
    stored = store.events(100_000)
    waiting = {e["id"] for e in store.outbox(100_000)}  # sent at the next start
    assert len(during) >= 10 and not waiting & during
    for rig in ("a", "b"):
        mine = {e["id"] for e in stored if e["rig"] == rig}
        sent = alarms(received, rig)
        assert all(e["rig"] == rig for e in sent)
        # nothing lost: each one the broker has (at least once), or still in the outbox
        assert {e["id"] for e in sent} | (waiting & mine) == mine
    assert bad == {"ok": False, "error": 'expected {"rule": NAME, "by": WHO}'}
    assert unknown == {"ok": False, "error": "b: no alarm rule 'melt'"}
    assert ack["ok"] and ack["events"][0]["by"] == "operator jane"
    acked = [e for e in stored if e["event"] == "acknowledged"]
    assert [(e["rig"], e["rule"], e["by"]) for e in acked] == [("b", "latched", "operator jane")]
    topics = {t for t, _, _ in received}
    assert {"plant/a/measurements", "plant/b/measurements", "plant/monitor/status"} <= topics
    states = [m["state"] for t, m, _ in received if t == "plant/monitor/status"]
    assert states[0] == "running" and states[-1] == "stopped"


def test_the_outbox_survives_a_restart_of_the_monitor(
    broker: Broker, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(PASSWORD_ENV, broker.password)
    got = Collector(broker, "plant/+/alarms")
    first = start_monitor(tmp_path, broker, [{"name": "a", "source": "sim"}])
    try:
        wait_for(lambda: first.store.count() >= 3)
        broker.stop()
        wait_for(lambda: len(first.store.outbox(100_000)) >= 5)
    finally:
        first.stop()  # with events still in its outbox
    waiting = EventStore(tmp_path / "store" / "events.sqlite")
    queued = {e["id"] for e in waiting.outbox()}
    waiting.close()
    assert len(queued) >= 5
    broker.start()
    wait_for(got.client.is_connected)
    # started again, with a broker that is back: the outbox goes first
    again = start_monitor(tmp_path, broker, [{"name": "a", "source": "sim:thermal=lepton3"}])
    try:
        wait_for(lambda: not outbox_ids(again) & queued)
        received = got.until(lambda out: queued <= {m["id"] for m in alarms(out, "a")})
    finally:
        again.stop()
    got.close()
    ids = {m["id"] for m in alarms(received, "a")}
    assert queued <= ids  # what waited on disk reached the broker after the restart


def test_a_broker_away_at_start_does_not_stop_the_monitor(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    broker = Broker()
    try:
        monkeypatch.setenv(PASSWORD_ENV, broker.password)
        settings = settings_file(tmp_path)
        path = monitor_config(
            tmp_path,
            [{"name": "a", "source": "sim", "settings": settings.name}],
            http={"listen": None},
            mqtt={"url": broker.url("plant"), "connect_timeout_s": 0.5},
        )
        monitor = Monitor(load_config(path))
        monitor.start()  # no broker yet
        try:
            wait_for(lambda: monitor.store.count() >= 3)
            assert any("MQTT: cannot reach mqtt://127.0.0.1:" in m for m in caplog.messages)
            waiting = outbox_ids(monitor)
            broker.start()
            wait_for(lambda: not outbox_ids(monitor) & waiting)  # the broker has them
        finally:
            monitor.stop()
        assert len(waiting) >= 3
        assert any(" is back after " in m for m in caplog.messages)
    finally:
        broker.cleanup()


def test_a_wrong_password_refuses_to_start(
    broker: Broker, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(PASSWORD_ENV, "wrong")
    path = monitor_config(tmp_path, [{"name": "a", "source": "sim"}], http={"listen": None},
                          mqtt={"url": broker.url("plant")})  # fmt: skip
    monitor = Monitor(load_config(path))
    with pytest.raises(InputError, match="refused the connection: Not authorized"):
        monitor.start()
    monitor.stop()  # what started is stopped
    assert not monitor.runners["a"].thread.is_alive()


STATE_TOPICS = {"plant/a/measurements", "plant/b/alarm_states", "plant/a/status",
                "plant/monitor/status"}  # fmt: skip
ROIS = """\
rois:
  - {name: plate, rect: [560, 280, 720, 440]}
  - {name: "wall top", rect: [0, 0, 1280, 100]}
"""


def render(template: str, payload: Any) -> str:
    """A Home Assistant value_template rendered as Home Assistant renders it (Jinja2, the
    payload as ``value_json``)."""
    import jinja2

    return jinja2.Environment().from_string(template).render(value_json=payload).strip()


def test_home_assistant_discovery(
    broker: Broker, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(PASSWORD_ENV, broker.password)
    settings_file(tmp_path, FLAPPING + ROIS)
    discovery = Collector(broker, "homeassistant/#", client_id="ha")
    states = Collector(broker, "plant/#", client_id="states")
    rigs = [{"name": "a", "source": "sim:pace=real", "location": "Hall 2"},
            {"name": "b", "source": "sim:pace=real,thermal=lepton3.5"}]  # fmt: skip
    path = monitor_config(tmp_path, [{**r, "settings": "s.yaml"} for r in rigs],
                          http={"listen": None},
                          mqtt={"url": broker.url("plant"), "homeassistant": True})  # fmt: skip
    node = "thermodepth_plant"
    want = {
        f"homeassistant/sensor/{node}/{rig}_{what}/config"
        for rig in "ab"
        for what in ("hottest", "roi_plate", "roi_wall_top")
    } | {
        f"homeassistant/binary_sensor/{node}/{rig}_{what}/config"
        for rig in "ab"
        for what in ("alarm_hot", "alarm_latched", "health")
    }
    monitor = Monitor(load_config(path))
    monitor.start()
    try:
        first = discovery.until(lambda out: {t for t, _, _ in out} >= want)
        # Home Assistant restarts and says so: every config again
        ha = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="home-assistant")
        ha.username_pw_set("rig", broker.password)
        ha.connect("127.0.0.1", broker.port)
        ha.loop_start()
        ha.publish("homeassistant/status", "online", qos=1).wait_for_publish(PATIENCE_S)
        again = discovery.until(lambda out: {t for t, _, _ in out} >= want)
        ha.disconnect()
        ha.loop_stop()
        heat = {t: m for t, m, _ in first}[
            f"homeassistant/binary_sensor/{node}/b_alarm_latched/config"
        ]

        def latched(out: list[tuple[str, Any, bool]]) -> bool:  # every state, b's alarm raised
            last = {t: m for t, m, _ in out}
            return (
                last.keys() >= STATE_TOPICS
                and render(heat["value_template"], last["plant/b/alarm_states"]) == "ON"
                and any(t == "plant/a/measurements" and m.get("hottest") for t, m, _ in out)
            )

        seen = states.until(latched)
    finally:
        monitor.stop()
    discovery.close()
    states.close()
    configs = {t: m for t, m, _ in first}
    assert set(configs) == want
    assert {t for t, _, _ in again if t.endswith("/config")} == want  # again, at its birth
    hottest = configs[f"homeassistant/sensor/{node}/a_hottest/config"]
    assert hottest["device_class"] == "temperature" and hottest["unit_of_measurement"] == "°C"
    assert hottest["state_class"] == "measurement"
    assert hottest["device"]["identifiers"] == ["thermodepth_plant_a"]
    assert hottest["device"]["suggested_area"] == "Hall 2"
    assert hottest["unique_id"] == "thermodepth_plant_a_hottest"
    for config in configs.values():  # what Home Assistant needs of every entity
        assert {"name", "unique_id", "state_topic", "device", "availability"} <= set(config)
    assert heat["device_class"] == "heat" and heat["state_topic"] == "plant/b/alarm_states"
    health = configs[f"homeassistant/binary_sensor/{node}/a_health/config"]
    assert health["device_class"] == "problem"
    # the states follow the rigs, read through the configs' own templates
    last = {t: m for t, m, _ in seen}
    # the last frame with a hotspot (a shutter frame's has none: Home Assistant's unknown)
    measured = next(
        m for t, m, _ in reversed(seen) if t == "plant/a/measurements" and m.get("hottest")
    )
    assert float(render(hottest["value_template"], measured)) == pytest.approx(
        measured["hottest"]["max_c"]
    )
    assert render(hottest["value_template"], {**measured, "hottest": None}) == "None"
    plate = configs[f"homeassistant/sensor/{node}/a_roi_plate/config"]
    assert float(render(plate["value_template"], measured)) == pytest.approx(
        measured["rois"]["plate"]["max_c"]
    )
    assert render(heat["value_template"], last["plant/b/alarm_states"]) == "ON"  # latched
    assert render(health["value_template"], last["plant/a/status"]) == "OFF"  # healthy
    available = [render(a["value_template"], last[a["topic"]]) for a in hottest["availability"]]
    assert available == ["online", "online"]
    gone = render(hottest["availability"][0]["value_template"], {"state": "died"})
    assert gone == "offline"  # the monitor's last will makes every entity unavailable


def test_home_assistant_entities_that_leave_the_config_are_removed(
    broker: Broker,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
) -> None:
    monkeypatch.setenv(PASSWORD_ENV, broker.password)
    settings_file(tmp_path, FLAPPING)
    mqtt_section = {"url": broker.url("plant"), "homeassistant": True}
    both = monitor_config(tmp_path, [{"name": n, "source": "sim", "settings": "s.yaml"}
                                     for n in "ab"], http={"listen": None},
                          mqtt=mqtt_section)  # fmt: skip
    configs = Collector(broker, "homeassistant/#", client_id="first")
    first = Monitor(load_config(both))
    first.start()
    configs.until(lambda out: len({t for t, m, _ in out if m}) == 8)  # 2 rigs, 4 entities each
    first.stop()
    configs.close()
    settings_file(tmp_path, "alarms:\n  - {name: hot, above_c: 67.48}\n")  # latched is gone
    one = monitor_config(tmp_path, [{"name": "a", "source": "sim", "settings": "s.yaml"}],
                         http={"listen": None}, mqtt=mqtt_section)  # fmt: skip
    second = Monitor(load_config(one))
    second.start()
    removed = lambda: sum("removed (no longer in the config)" in m for m in caplog.messages)  # noqa: E731
    wait_for(lambda: removed() == 5)
    second.stop()
    retained = Collector(broker, "homeassistant/#", client_id="late")
    kept = {t for t, m, _ in retained.drain(settle_s=0.5)}
    retained.close()
    node = "thermodepth_plant"
    assert kept == {
        f"homeassistant/sensor/{node}/a_hottest/config",
        f"homeassistant/binary_sensor/{node}/a_alarm_hot/config",
        f"homeassistant/binary_sensor/{node}/a_health/config",
    }
    assert removed() == 5


def test_a_monitor_that_cannot_start_publishes_nothing(
    broker: Broker, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import socket

    monkeypatch.setenv(PASSWORD_ENV, broker.password)
    got = Collector(broker, "plant/#")
    with socket.socket() as taken:  # its HTTP port is someone else's
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        path = monitor_config(
            tmp_path,
            [{"name": "a", "source": "sim", "settings": settings_file(tmp_path).name}],
            http={"listen": f"127.0.0.1:{port}"},
            mqtt={"url": broker.url("plant"), "homeassistant": True},
        )
        monitor = Monitor(load_config(path))
        with pytest.raises(InputError, match=f"http.listen: 127.0.0.1:{port}: cannot listen"):
            monitor.start()
    # a marker sent after it gave up: whatever it had published would have come before it
    marker = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="marker")
    marker.username_pw_set("rig", broker.password)
    marker.connect("127.0.0.1", broker.port)
    marker.loop_start()
    marker.publish("plant/marker", "{}", qos=1).wait_for_publish(PATIENCE_S)
    marker.disconnect()
    marker.loop_stop()
    received = got.until(lambda out: any(t == "plant/marker" for t, _, _ in out))
    got.close()
    assert [t for t, _, _ in received] == ["plant/marker"]  # no status, no alarm states
