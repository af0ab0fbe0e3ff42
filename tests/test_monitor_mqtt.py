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

from monitor_helpers import monitor_config, settings_file, wait_for
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
    monitor = Monitor(load_config(path), lambda line: None)
    monitor.start()
    return monitor


def alarms(received: list[tuple[str, Any, bool]], rig: str) -> list[dict[str, Any]]:
    return [m for t, m, _ in received if t == f"plant/{rig}/alarms"]


def command(broker: Broker, topic: str, payload: str) -> dict[str, Any]:
    """Publish ``payload`` to ``topic`` and return the answer on ``topic/result``."""
    answers = Collector(broker, f"{topic}/result", client_id=f"ack-{time.monotonic_ns()}")
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="operator")
    c.username_pw_set("rig", broker.password)
    c.connect("127.0.0.1", broker.port)
    c.loop_start()
    c.publish(topic, payload, qos=1).wait_for_publish(5)
    got = answers.messages.get(timeout=5)
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
        time.sleep(2.5)
        broker.stop()
        time.sleep(2.0)  # alarms go on, into the outbox
        during = monitor.store.count()
        broker.start()
        time.sleep(2.5)  # the monitor and the collector reconnect (1-2 s)
        bad = command(broker, "plant/b/ack", '{"rule": "latched"}')
        unknown = command(broker, "plant/b/ack", '{"rule": "melt", "by": "jane"}')
        ack = command(broker, "plant/b/ack", '{"rule": "latched", "by": "operator jane"}')
        time.sleep(0.5)
    finally:
        monitor.stop()
    received = got.drain(settle_s=1.0)
    got.close()
    store = EventStore(tmp_path / "store" / "events.sqlite")
    stored = store.events(100_000)
    assert store.outbox() == []  # every one acknowledged by the broker
    assert during > 10
    for rig in ("a", "b"):
        mine = [e for e in stored if e["rig"] == rig]
        sent = alarms(received, rig)
        assert {e["id"] for e in sent} == {e["id"] for e in mine}  # every one, no other
        assert all(e["rig"] == rig for e in sent)
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
        wait_for(lambda: first.store.count() >= 3, 10)
        broker.stop()
        time.sleep(2.0)
    finally:
        first.stop()  # with events still in its outbox
    waiting = EventStore(tmp_path / "store" / "events.sqlite")
    queued = {e["id"] for e in waiting.outbox()}
    waiting.close()
    assert len(queued) >= 5
    broker.start()
    wait_for(got.client.is_connected, 10)
    # started again, with a broker that is back: the outbox goes first
    again = start_monitor(tmp_path, broker, [{"name": "a", "source": "sim:thermal=lepton3"}])
    try:
        wait_for(lambda: again.store.outbox(10_000) == [] and again.store.count() > 0, 10)
        received = got.drain(settle_s=1.0)
    finally:
        again.stop()
    got.close()
    ids = {m["id"] for m in alarms(received, "a")}
    assert queued <= ids  # what waited on disk reached the broker after the restart


def test_a_broker_away_at_start_does_not_stop_the_monitor(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    broker = Broker()
    try:
        monkeypatch.setenv(PASSWORD_ENV, broker.password)
        lines: list[str] = []
        settings = settings_file(tmp_path)
        path = monitor_config(
            tmp_path,
            [{"name": "a", "source": "sim", "settings": settings.name}],
            http={"listen": None},
            mqtt={"url": broker.url("plant"), "connect_timeout_s": 0.5},
        )
        monitor = Monitor(load_config(path), lines.append)
        monitor.start()  # no broker yet
        try:
            wait_for(lambda: monitor.store.count() >= 3, 10)
            assert any("MQTT: cannot reach mqtt://127.0.0.1:" in line for line in lines)
            waiting = len(monitor.store.outbox(10_000))
            broker.start()
            wait_for(lambda: not monitor.store.outbox(10_000), 10)  # the broker has them
        finally:
            monitor.stop()
        assert waiting >= 3
        assert any(" is back after " in line for line in lines)
    finally:
        broker.cleanup()


def test_a_wrong_password_refuses_to_start(
    broker: Broker, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(PASSWORD_ENV, "wrong")
    path = monitor_config(tmp_path, [{"name": "a", "source": "sim"}], http={"listen": None},
                          mqtt={"url": broker.url("plant")})  # fmt: skip
    monitor = Monitor(load_config(path), lambda line: None)
    with pytest.raises(InputError, match="refused the connection: Not authorized"):
        monitor.start()
    monitor.stop()  # what started is stopped
    assert not monitor.runners["a"].thread.is_alive()
