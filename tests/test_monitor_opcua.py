"""The monitor's OPC UA server read by an independent client (asyncua's): values equal the
measurements of the same frames computed apart, alarm events, a wrong password and anonymous
sessions refused, the Basic256Sha256 policy with the server's own certificate."""

from __future__ import annotations

import asyncio
import math
import time
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("asyncua", reason="the OPC UA server needs the opcua extra (asyncua)")

from asyncua import Client, ua

from monitor_helpers import FLAPPING, PATIENCE_S, monitor_config, settings_file, wait_for
from thermodepth.monitor import Monitor, load_config
from thermodepth.pipeline import Pipeline, Settings
from thermodepth.session import record_session
from thermodepth.sources import open_source

ROIS = "rois:\n  - {name: plate, rect: [560, 280, 720, 440]}\n  - {name: nothing, depth_range_m: [5, 6]}\n"  # noqa: E501


def start(folder: Path, rigs: list[dict[str, Any]], **opcua: Any) -> tuple[Monitor, str]:
    settings_file(folder, FLAPPING + ROIS)
    (folder / "users.yaml").write_text("jane: s3cret\n")
    from mqtt_broker import free_port

    endpoint = f"opc.tcp://127.0.0.1:{free_port()}/thermodepth"
    path = monitor_config(
        folder,
        [{"settings": "s.yaml", **r} for r in rigs],
        http={"listen": None},
        opcua={"endpoint": endpoint, "users_file": "users.yaml", **opcua},
    )
    monitor = Monitor(load_config(path))
    monitor.start()
    return monitor, endpoint


async def read(endpoint: str, paths: list[str], user: str = "jane", password: str = "s3cret",
               security: str | None = None) -> dict[str, Any]:  # fmt: skip
    client = Client(endpoint, timeout=30)
    if user:
        client.set_user(user)
        client.set_password(password)
    if security:
        await client.set_security_string(security)
    async with client:
        ns = await client.get_namespace_index("urn:thermodepth:monitor")
        out = {}
        for p in paths:
            out[p] = await client.get_node(f"ns={ns};s={p}").read_data_value()
        return out


def test_values_equal_the_measurements_of_the_same_frame(tmp_path: Path) -> None:
    take = tmp_path / "take.zarr"
    record_session(open_source("sim", frames=12), take)
    settings_file(tmp_path, FLAPPING + ROIS)
    # the same recording measured apart, as `run` would
    with open_source(f"recording:{take}") as src:
        pipe = Pipeline(Settings.load(tmp_path / "s.yaml"), src.calibration)
        last = [pipe.process(p) for p in src][-1]
    plate = next(r for r in last.rois if r.name == "plate")
    monitor, endpoint = start(
        tmp_path, [{"name": "r", "source": f"recording:{take}", "pace": "fast"}]
    )

    def the_last_frame() -> dict[str, Any] | None:  # held back, it is written by the clock
        got = asyncio.run(read(endpoint, [
            "r.Hottest", "r.VoxTemperature", "r.Rois.plate.Max", "r.Rois.plate.Mean",
            "r.Rois.plate.Min", "r.Rois.nothing.Max", "r.Alarms.latched.Raised",
            "r.Alarms.latched.Level", "r.Alarms.latched.State", "r.Health",
        ]))  # fmt: skip
        stamp = got["r.Rois.plate.Max"].SourceTimestamp
        written = stamp and abs(stamp.timestamp() - last.thermal_time_s) < 1e-3
        # an ended replay is not stale (its health written each second by the clock)
        return got if written and got["r.Health"].Value.Value == "ok" else None

    try:
        wait_for(lambda: monitor.runners["r"].status.state == "ended")
        got = wait_for(the_last_frame, every_s=0.2)
    finally:
        monitor.stop()
    assert got["r.Hottest"].Value.Value == last.hotspots[0].max_c
    assert got["r.VoxTemperature"].Value.Value == last.vox_temp_c
    assert got["r.Rois.plate.Max"].Value.Value == plate.max_c
    assert got["r.Rois.plate.Mean"].Value.Value == plate.mean_c
    assert got["r.Rois.plate.Min"].Value.Value == plate.min_c
    assert math.isnan(got["r.Rois.nothing.Max"].Value.Value)  # no valid pixel
    assert got["r.Rois.plate.Max"].Value.VariantType == ua.VariantType.Double
    stamp = got["r.Rois.plate.Max"].SourceTimestamp.timestamp()
    assert stamp == pytest.approx(last.thermal_time_s, abs=1e-3)  # the frame's time
    assert got["r.Alarms.latched.Raised"].Value.Value is True
    assert got["r.Alarms.latched.Level"].Value.Value == "alarm"
    assert got["r.Alarms.latched.State"].Value.Value == "alarm"
    assert got["r.Health"].Value.Value == "ok"  # an ended replay is not stale


async def events_of(endpoint: str) -> list[Any]:
    """The rig's OPC UA events until an alarm and a clear of ``hot`` have come."""
    client = Client(endpoint, timeout=30)
    client.set_user("jane")
    client.set_password("s3cret")
    got: list[Any] = []

    class Handler:
        def event_notification(self, event: Any) -> None:
            got.append(event)

    async with client:
        ns = await client.get_namespace_index("urn:thermodepth:monitor")
        rig = client.get_node(f"ns={ns};s=a")
        sub = await client.create_subscription(50, Handler())
        await sub.subscribe_events(rig)
        end = time.monotonic() + PATIENCE_S
        while time.monotonic() < end and not {"ALARM", "CLEAR"} <= {
            e.Message.Text.split()[0] for e in got if e.SourceName == "hot"
        }:
            await asyncio.sleep(0.1)
    return got


def test_alarm_events_and_who_may_connect(tmp_path: Path) -> None:
    monitor, endpoint = start(tmp_path, [{"name": "a", "source": "sim"}])
    try:
        wait_for(lambda: monitor.store.count() >= 2)
        events = asyncio.run(events_of(endpoint))
        with pytest.raises(ua.UaStatusCodeError, match="BadUserAccessDenied"):
            asyncio.run(read(endpoint, ["a.Health"], password="wrong"))
        with pytest.raises(ua.UaStatusCodeError, match=r"\(BadIdentityTokenRejected\)"):
            asyncio.run(read(endpoint, ["a.Health"], user=""))  # anonymous: off
    finally:
        monitor.stop()
    hot = [e for e in events if e.SourceName == "hot"]
    assert len(hot) >= 2
    lines = [e.Message.Text for e in hot]
    assert any(line.startswith("ALARM hot [alarm]") for line in lines)
    assert any(line.startswith("CLEAR hot [alarm]") for line in lines)
    assert {e.Severity for e in hot} <= {800, 100}


def test_basic256sha256_with_the_servers_own_certificate(tmp_path: Path) -> None:
    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    key, cert = tmp_path / "client-key.pem", tmp_path / "client-cert.der"
    asyncio.run(setup_self_signed_certificate(
        key, cert, "urn:thermodepth:test-client", "localhost",
        [ExtendedKeyUsageOID.CLIENT_AUTH], {"commonName": "test client"},
    ))  # fmt: skip
    monitor, endpoint = start(
        tmp_path, [{"name": "a", "source": "sim"}], security=["basic256sha256"]
    )
    try:
        wait_for(lambda: monitor.runners["a"].status.frames > 3)
        secure = f"Basic256Sha256,SignAndEncrypt,{cert},{key}"

        def once_up() -> dict[str, Any] | None:  # the server's values follow the rig's status
            got = asyncio.run(read(endpoint, ["a.Health", "a.Up"], security=secure))
            return got if got["a.Up"].Value.Value else None

        got = wait_for(once_up, every_s=0.5)
        with pytest.raises(Exception):  # noqa: B017  no policy "none" offered
            asyncio.run(read(endpoint, ["a.Health"]))
    finally:
        monitor.stop()
    assert got["a.Up"].Value.Value is True
    assert (tmp_path / "store" / "opcua" / "server-cert.der").stat().st_size > 500  # made


def test_opcua_config_problems(tmp_path: Path) -> None:
    from thermodepth.errors import InputError

    path = monitor_config(tmp_path, [{"name": "a", "source": "sim"}],
                          opcua={"endpoint": "http://x"})  # fmt: skip
    with pytest.raises(InputError) as info:
        load_config(path)
    lines = [line.removeprefix(f"{path}: ") for line in str(info.value).splitlines()]
    assert lines == [
        "opcua.endpoint: 'http://x': expected opc.tcp://HOST:PORT/PATH "
        "(opc.tcp://127.0.0.1:4840/thermodepth)",
        "opcua: nobody could connect: give users_file (user: password), or anonymous: true",
    ]
