"""`run --mqtt`: alarms, measurements and status on a real Mosquitto broker started by the
tests (skipped, naming the package, where it is not installed)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("paho.mqtt.client", reason="--mqtt needs the mqtt extra (paho-mqtt)")

from chip_settings import chip_settings
from monitor_helpers import wait_for
from mqtt_broker import Broker, Collector, missing
from thermodepth.app.run import RunOptions, run
from thermodepth.errors import FieldError, InputError
from thermodepth.sinks import CallbackSink
from thermodepth.sinks.mqtt import PASSWORD_ENV, MqttTarget

needs_broker = pytest.mark.skipif(missing() is not None, reason=missing() or "")


MQTT = "mqtt:\n  measurements_hz: 1000\n"


@pytest.fixture()
def settings(tmp_path: Path) -> Path:
    return chip_settings(tmp_path, MQTT)


@pytest.fixture()
def broker(request: pytest.FixtureRequest) -> Broker:
    b = Broker(persistence=getattr(request, "param", False))
    try:
        b.start()
        yield b
    finally:
        b.cleanup()


def alarms_file(out: Path) -> list[dict]:  # type: ignore[type-arg]
    lines = (out / "alarms.jsonl").read_text(encoding="utf-8").splitlines()
    return [json.loads(x) for x in lines]


def key(m: dict) -> tuple:  # type: ignore[type-arg]
    return (m["event"], m["rule"], m["frame"])


@needs_broker
def test_alarms_and_measurements_reach_the_broker(
    broker: Broker, settings: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(PASSWORD_ENV, broker.password)
    got = Collector(broker, "plant/rig1/#")
    lines: list[str] = []
    result = run(
        RunOptions("sim", settings, 30, tmp_path / "out", mqtt=broker.url()), warn=lines.append
    )
    received = got.drain()
    got.close()
    want = alarms_file(tmp_path / "out")
    assert len(want) >= 4  # the test means something
    alarms = [m for t, m, _ in received if t == "plant/rig1/alarms"]
    assert sorted(map(key, alarms)) == sorted(map(key, want))  # every one, nothing else
    first = next(m for m in alarms if m["event"] == "alarm")
    assert len(first["position_m"]) == 3 and 0.9 < first["distance_m"] < 1.1
    measurements = [m for t, m, _ in received if t == "plant/rig1/measurements"]
    assert len(measurements) >= 20 and measurements[-1]["hottest"]["max_c"] > 60
    states = [m["state"] for t, m, _ in received if t == "plant/rig1/status"]
    assert states[0] == "running" and states[-1] == "stopped"
    assert not lines  # no outage to tell
    summary = next(line for line in result.outputs if line.startswith("MQTT"))
    assert f"{len(want)} alarm events published ({len(want)} acknowledged)" in summary
    # the status stays on the broker for whoever looks later
    late = Collector(broker, "plant/rig1/status", client_id="late")
    retained = late.drain()
    late.close()
    assert [(m["state"], r) for _, m, r in retained] == [("stopped", True)]


@needs_broker
@pytest.mark.parametrize("broker", [True], indirect=True)  # a broker that keeps sessions
def test_a_broker_that_goes_away_loses_no_alarm(
    broker: Broker, settings: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(PASSWORD_ENV, broker.password)
    got = Collector(broker, "plant/rig1/alarms")
    lines: list[str] = []

    def outage(fused: object) -> None:
        index = fused.index  # type: ignore[attr-defined]
        if index == 8:
            broker.stop()
            wait_for(lambda: any(line.startswith("MQTT: lost") for line in lines))
        elif index == 20:
            broker.start()  # the run and the collector reconnect by themselves
            wait_for(lambda: any(" is back after " in line for line in lines))
            wait_for(got.client.is_connected)

    result = run(
        RunOptions("sim", settings, 32, tmp_path / "out", mqtt=broker.url()),
        [CallbackSink(outage)],
        warn=lines.append,
    )
    received = got.drain(settle_s=1.0)
    got.close()
    want = alarms_file(tmp_path / "out")
    during = [e for e in want if 8 <= e["frame"] < 20]
    assert during, "alarms happened while the broker was away"
    assert sorted(set(map(key, (m for _, m, _ in received)))) == sorted(map(key, want))
    assert any(line.startswith("MQTT: lost mqtt://127.0.0.1:") for line in lines)
    assert any(" is back after " in line for line in lines)
    summary = next(line for line in result.outputs if line.startswith("MQTT"))
    assert "NOT delivered" not in summary and "the broker was away 1 times" in summary


@needs_broker
def test_wrong_password_is_one_line(
    broker: Broker, settings: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(PASSWORD_ENV, "wrong")
    with pytest.raises(InputError) as info:
        run(RunOptions("sim", settings, 3, tmp_path / "out", mqtt=broker.url()))
    message = str(info.value)
    assert "\n" not in message
    assert message == (
        f"mqtt://127.0.0.1:{broker.port}: the MQTT broker refused the connection: Not authorized "
        "(reason code 135) (wrong username or password?)"
    )


@needs_broker
def test_last_will_says_the_run_died(broker: Broker, settings: Path, tmp_path: Path) -> None:
    env = {**os.environ, PASSWORD_ENV: broker.password}
    cmd = [sys.executable, "-m", "thermodepth.cli", "run", "--source", "sim", "--quiet",
           "--settings", str(settings), "--mqtt", broker.url()]  # fmt: skip
    watch = Collector(broker, "plant/rig1/status", client_id="watch")
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        _, first, _ = watch.messages.get(timeout=60)  # numba's cache, the sim's first frames
        assert first["state"] == "running"
        proc.kill()  # no goodbye: the broker speaks the will
        _, last, _ = watch.messages.get(timeout=30)
    finally:
        proc.kill()
        proc.wait()
        watch.close()
    assert last == {"state": "died", "source": "sim"}


@needs_broker
def test_password_file_from_the_settings(broker: Broker, tmp_path: Path) -> None:
    (tmp_path / "pw").write_text(broker.password + "\n", encoding="utf-8")
    path = chip_settings(tmp_path, MQTT + "  password_file: pw\n")
    result = run(RunOptions("sim", path, 2, mqtt=broker.url()))
    assert any(line.startswith("MQTT mqtt://127.0.0.1") for line in result.outputs)


@pytest.mark.parametrize(
    ("url", "message"),
    [
        ("http://h/p", "expected mqtt://[USER@]HOST[:PORT]/PREFIX"),
        ("mqtt://h", "give a topic prefix"),
        ("mqtt://h/a/#", "give a topic prefix"),
        ("mqtt://u:pw@h/p", "a password in the URL would show in the process list"),
        ("mqtt://h:port/p", "the port is not a number"),
    ],
)
def test_bad_urls_are_one_line(url: str, message: str) -> None:
    with pytest.raises(FieldError, match=r"^mqtt: ") as info:
        MqttTarget.parse(url)
    assert message in str(info.value)


def test_url_parts() -> None:
    t = MqttTarget.parse("mqtts://op%40plant@broker.local/plant/rig1/")
    assert (t.tls, t.host, t.port, t.prefix, t.username) == (
        True,
        "broker.local",
        8883,
        "plant/rig1",
        "op@plant",
    )
    assert MqttTarget.parse("mqtt://b:1884/x").port == 1884


def test_unreachable_broker_is_one_line(settings: Path, tmp_path: Path) -> None:
    from mqtt_broker import free_port

    port = free_port()
    with pytest.raises(
        InputError, match=rf"^mqtt://127.0.0.1:{port}: cannot reach the MQTT broker"
    ):
        run(RunOptions("sim", settings, 2, mqtt=f"mqtt://127.0.0.1:{port}/p"))
