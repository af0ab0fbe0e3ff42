"""The monitor's parts on their own: its config (every problem a line), the event store
(versioned schema, migrated; outbox), the fail-safe's faults, the pre-trigger buffer (bit for
bit), the storage rule, a recording replayed at its recorded pace, systemd's notify protocol
and the CLI's --check."""

from __future__ import annotations

import os
import re
import shutil
import socket
import sqlite3
import threading
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from monitor_helpers import FLAPPING, monitor_config, settings_file
from thermodepth.compensation import preset
from thermodepth.compensation.files import save_model
from thermodepth.errors import InputError
from thermodepth.frames import FfcState, Telemetry, match_of
from thermodepth.monitor import storage
from thermodepth.monitor.config import FailsafeConfig, StorageConfig, load_config
from thermodepth.monitor.evidence import PackedMatch, PreTrigger
from thermodepth.monitor.failsafe import Fault, SensorWatch
from thermodepth.monitor.rig import PacedSource
from thermodepth.monitor.storage import ContinuousRecorder, Retention, stamp
from thermodepth.monitor.store import MIGRATIONS, EventStore
from thermodepth.monitor.systemd import notify, watchdog_interval_s
from thermodepth.pipeline import PixelFlag
from thermodepth.session import record_session
from thermodepth.sources import open_source

# -- the config ---------------------------------------------------------------------------------


EXAMPLES = Path(__file__).parents[1] / "examples"


def test_the_example_config_is_valid_beside_the_files_its_settings_name(tmp_path: Path) -> None:
    # as it is, its settings name a calibration and a model that a rig's folder will hold:
    # said, each with the rig, the settings file and the key (not "OK", then a failed start)
    with pytest.raises(InputError) as info:
        load_config(EXAMPLES / "monitor.yaml")
    assert str(info.value).splitlines()[:2] == [
        f"{EXAMPLES / 'monitor.yaml'}: rigs.0 (cabinet-4).settings: "
        f"{EXAMPLES / 'settings.yaml'}: calibration: {EXAMPLES / 'calib.yaml'}: cannot read "
        "(No such file or directory)",
        f"{EXAMPLES / 'monitor.yaml'}: rigs.0 (cabinet-4).settings: "
        f"{EXAMPLES / 'settings.yaml'}: compensation: {EXAMPLES / 'model.json'}: cannot read "
        "(No such file or directory)",
    ]
    for name in ("monitor.yaml", "settings.yaml"):
        shutil.copy(EXAMPLES / name, tmp_path / name)
    shutil.copy(EXAMPLES / "calibration.yaml", tmp_path / "calib.yaml")
    save_model(preset("paper2022"), tmp_path / "model.json")
    config = load_config(tmp_path / "monitor.yaml")
    assert [r.name for r in config.rigs] == ["cabinet-4", "rehearsal"]
    assert config.http.listen == "127.0.0.1:8088" and config.storage.pre_s == 10


def test_a_settings_file_naming_a_broken_model_or_calibration_is_refused(tmp_path: Path) -> None:
    (tmp_path / "broken.json").write_text("{", encoding="utf-8")
    settings_file(tmp_path, "calibration: nope.yaml\ncompensation: broken.json\n", "s.yaml")
    path = monitor_config(tmp_path, [{"name": "press7", "source": "sim", "settings": "s.yaml"}])
    with pytest.raises(InputError) as info:
        load_config(path)
    lines = str(info.value).splitlines()
    where = f"{path}: rigs.0 (press7).settings: {tmp_path / 's.yaml'}"
    assert lines[0] == (
        f"{where}: calibration: {tmp_path / 'nope.yaml'}: cannot read (No such file or directory)"
    )
    assert lines[1].startswith(f"{where}: compensation: {tmp_path / 'broken.json'}: ")
    assert len(lines) == 2


def test_every_problem_of_a_config_is_a_line(tmp_path: Path) -> None:
    path = tmp_path / "m.yaml"
    path.write_text(
        yaml.safe_dump(
            {
                "rigs": [
                    {"name": "a b", "source": "sim"},
                    {"name": "monitor", "source": "sim", "stall_s": 0},
                ],
                "storage": {"path": "s", "colour": "red"},
            }
        ),
        encoding="utf-8",
    )
    with pytest.raises(InputError) as info:
        load_config(path)
    assert str(info.value).splitlines() == [
        f"{path}: rigs.0.name: use letters, digits and _.- only (it names topics and "
        "folders) (got 'a b')",
        f"{path}: rigs.1.name: 'monitor' names the monitor's own events: choose another "
        "(got 'monitor')",
        f"{path}: rigs.1.stall_s: Input should be greater than 0 (got 0)",
        f"{path}: storage.colour: unknown key",
    ]


def test_a_config_checks_sources_settings_and_who_may_listen(tmp_path: Path) -> None:
    path = monitor_config(
        tmp_path,
        [
            {"name": "a", "source": "webcam"},
            {"name": "a", "source": "sim:faults=melt@1s", "settings": "none.yaml"},
            {"name": "r", "source": "recording:take.zarr", "pace": "fast"},
            {"name": "s", "source": "sim", "pace": "recorded"},
        ],
        http={"listen": "0.0.0.0:8088"},
        mqtt={"url": "mqtt://broker"},
    )
    with pytest.raises(InputError) as info:
        load_config(path)
    lines = [line.removeprefix(f"{path}: ") for line in str(info.value).splitlines()]
    assert lines[0] == "rigs: names must differ: 'a' twice"
    assert lines[1].startswith("rigs.0 (a).source: unknown 'webcam'; expected one of sim[")
    assert lines[2].startswith("rigs.1 (a).source: faults: 'melt@1s': expected KIND@Ts")
    assert (
        lines[3]
        == f"rigs.1 (a).settings: {tmp_path / 'none.yaml'}: cannot read (No such file or directory)"
    )
    assert lines[4] == f"rigs.2 (r).source: {tmp_path / 'take.zarr'}: no such recording"
    assert lines[5] == "rigs.3 (s).pace: only a recording: source has a pace to choose"
    assert lines[6] == (
        "http.listen: 0.0.0.0:8088 is reachable from other machines: give http.token_file "
        "(or THERMODEPTH_HTTP_TOKEN), or listen on 127.0.0.1"
    )
    assert (
        lines[7] == "mqtt.url: 'mqtt://broker': give a topic prefix without wildcards (/plant/rig1)"
    )
    assert len(lines) == 8


def test_monitor_check_says_what_the_config_sets_up(tmp_path: Path, cli_process: Any) -> None:
    path = monitor_config(tmp_path, [{"name": "a", "source": "sim", "location": "bay 1"}])
    done = cli_process("monitor", str(path), "--check")
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [
        "1 rig:",
        "  a at bay 1: sim with default settings",
        "    ROIs: none; alarm rules: none",
        "    calibration: none",
        "    compensation: none",
        f"storage {tmp_path / 'store'}: clips of events, 1 s before and 1 s after; kept 30 "
        "days, 1 GB left free",
        "HTTP on 127.0.0.1:0",
        "no outputs (MQTT, OPC UA, Modbus, RTSP, notifications): the dashboard and the log only",
        "log level info",
        f"{path}: OK",
    ]
    settings_file(tmp_path, FLAPPING + "rois:\n  - {name: plate, rect: [0, 0, 10, 10]}\n")
    (tmp_path / "users.yaml").write_text("jane: s3cret\n", encoding="utf-8")
    path = monitor_config(
        tmp_path,
        [{"name": "a", "source": "sim", "settings": "s.yaml"}],
        mqtt={"url": "mqtt://broker:1883/plant", "homeassistant": True},
        opcua={"users_file": "users.yaml"},
        log={"level": "warning", "rigs": {"a": "debug"}},
    )
    lines = cli_process("monitor", str(path), "--check").stdout.splitlines()
    assert lines[2:5] == [
        "    ROIs: plate; alarm rules: hot (above 67.48 C for 1 frame), latched (above 60 C "
        "for 1 frame, latched until acknowledged)",
        "    calibration: none",
        "    compensation: none",
    ]
    assert lines[-4:] == [
        "MQTT mqtt://broker:1883/plant (readings 1/s, snapshots 1/s); Home Assistant "
        "discovery on (under homeassistant/)",
        f"OPC UA opc.tcp://127.0.0.1:4840/thermodepth (security none, basic256sha256; users "
        f"from {tmp_path / 'users.yaml'})",
        "log level warning (a debug)",
        f"{path}: OK",
    ]
    path.write_text("rigs: []\nstorage: {path: s}\n", encoding="utf-8")
    bad = cli_process("monitor", str(path), "--check")
    assert bad.returncode == 2
    assert "rigs: List should have at least 1 item after validation" in bad.stderr


# -- the event store --------------------------------------------------------------------------


def event(n: int, **extra: Any) -> dict[str, Any]:
    return {
        "rig": "a",
        "rule": "hot",
        "level": "alarm",
        "event": "alarm",
        "time_utc": "2026-11-26T10:00:00.000+00:00",
        "time_s": 1.0 * n,
        "frame": n,
        **extra,
    }


def test_the_store_keeps_events_newest_first_and_its_outbox(tmp_path: Path) -> None:
    store = EventStore(tmp_path / "e.sqlite")
    targets = [("mqtt", "webhook:ops") if n % 2 == 0 else ("webhook:ops",) if n == 1 else ()
               for n in range(5)]  # fmt: skip
    ids = [store.add(event(n, clip=f"a/{n}"), outbox=targets[n]) for n in range(5)]
    assert [e["id"] for e in store.events()] == ids[::-1]
    assert [e["frame"] for e in store.events(2, before_id=ids[3])] == [2, 1]
    assert [e["id"] for e in store.outbox(target="mqtt")] == [ids[0], ids[2], ids[4]]
    store.delivered(ids[2], "mqtt")
    assert [e["id"] for e in store.outbox(after_id=ids[0], target="mqtt")] == [ids[4]]
    # each output its own rows: the broker's delivery leaves the webhook's
    assert [e["id"] for e in store.outbox(target="webhook:ops")] == ids[:3] + ids[4:]
    store.delivered(ids[0], "webhook:ops")
    assert store.waiting("webhook:ops") == 3 and store.waiting("mqtt") == 2
    assert [e["id"] for e in store.outbox()] == [ids[0], ids[1], ids[2], ids[4]]  # for anyone
    store.clip_deleted("a/1")
    assert [e["clip_kept"] for e in store.events()] == [True, True, True, False, True]
    store.close()
    again = EventStore(tmp_path / "e.sqlite")  # what was written stays
    assert again.count() == 5 and [e["id"] for e in again.outbox(target="mqtt")] == [
        ids[0], ids[4]
    ]  # fmt: skip
    mode = again.db.execute("PRAGMA journal_mode").fetchone()[0]
    assert mode == "wal"


def test_the_schema_is_versioned_and_migrated(tmp_path: Path) -> None:
    path = tmp_path / "e.sqlite"
    old = EventStore(path)
    old.add(event(1))
    old.close()
    step = "ALTER TABLE events ADD COLUMN shift TEXT; UPDATE events SET shift = 'night'"
    newer = EventStore(path, (*MIGRATIONS, step))
    assert newer.version == len(MIGRATIONS) + 1
    assert newer.db.execute("SELECT shift FROM events").fetchall() == [("night",)]
    assert newer.count() == 1
    newer.close()
    n = len(MIGRATIONS)
    with pytest.raises(InputError, match=rf"event store of version {n + 1}, newer than this "
                       rf"thermodepth reads \({n}\): upgrade thermodepth"):  # fmt: skip
        EventStore(path)
    broken = tmp_path / "b.sqlite"
    EventStore(broken).close()
    with pytest.raises(InputError, match=rf"cannot migrate the event store from version {n} to "
                       rf"{n + 1} \(no such table: nowhere\)"):  # fmt: skip
        EventStore(broken, (*MIGRATIONS, "ALTER TABLE nowhere ADD COLUMN x"))
    assert EventStore(broken).version == n  # a failed step leaves the file as it was
    first = EventStore(tmp_path / "v1.sqlite", MIGRATIONS[:1])  # as the first monitor wrote it
    first.db.execute("INSERT INTO events (rig, rule, level, state, time_utc, body) "
                     "VALUES ('a', 'hot', 'alarm', 'alarm', 'T', '{}')")  # fmt: skip
    first.close()
    now = EventStore(tmp_path / "v1.sqlite")
    assert now.version == n and now.count() == 1
    now.add({**event(2), "origin": "edge1/a#7"})
    with pytest.raises(sqlite3.IntegrityError):
        now.add({**event(3), "origin": "edge1/a#7"})  # a central dashboard's copy: once
    now.close()
    two = EventStore(tmp_path / "v2.sqlite", MIGRATIONS[:2])  # one outbox: the broker's
    kept = [two.add(event(n)) for n in range(3)]
    two.db.executemany("INSERT INTO outbox (event_id) VALUES (?)", [(kept[0],), (kept[2],)])
    two.close()
    three = EventStore(tmp_path / "v2.sqlite")
    assert three.version == n
    assert [e["id"] for e in three.outbox(target="mqtt")] == [kept[0], kept[2]]
    assert three.outbox(target="webhook:ops") == []
    three.add(event(4), outbox=("mqtt", "webhook:ops"))
    assert three.waiting("mqtt") == 3 and three.waiting("webhook:ops") == 1
    three.close()


def test_a_file_that_is_not_a_store_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "e.sqlite"
    path.write_bytes(b"not a database at all" * 100)
    with pytest.raises(InputError, match=rf"^{path}: not an event store \("):
        EventStore(path)


# -- the fail-safe ------------------------------------------------------------------------------


def test_a_fault_waits_its_on_delay_and_its_clear_delay() -> None:
    f = Fault("sensor_fault", "corrupt", on_s=1.0, clear_s=0.5)
    assert f.update(0.0, True, "bad") is None and f.update(0.9, True, "bad") is None
    raised = f.update(1.0, True, "bad", frame=7)
    assert raised is not None and raised["event"] == "alarm" and raised["frame"] == 7
    assert f.update(1.5, True, "bad") is None  # once
    assert f.update(2.0, False) is None and f.update(2.2, True, "bad") is None
    assert f.update(2.4, False) is None  # the clear delay starts again
    ack = f.acknowledge("jane", 2.5, 9)
    assert ack["event"] == "acknowledged" and ack["by"] == "jane"
    cleared = f.update(2.9, False)
    assert cleared is not None and cleared["acknowledged"]["by"] == "jane"


def frame(index: int, vox_c: float = 35.0, in_ffc: bool = False, bad: float = 0.0) -> Any:
    flags = np.zeros((12, 16), np.uint8)
    flags.flat[: int(bad * flags.size)] = PixelFlag.BAD_COUNTS
    return SimpleNamespace(index=index, vox_temp_c=vox_c, in_ffc=in_ffc, flags_thermal=flags)


def kinds(events: list[dict[str, Any]]) -> list[tuple[str, str]]:
    return [(e["event"], e["fault"]) for e in events]


def test_sensor_watch_vox_corrupt_and_shutter() -> None:
    config = FailsafeConfig(vox_margin_c=1, corrupt_s=0.5, clear_s=0.5, shutter_max_s=2,
                            shutter_window_s=4, shutter_max_share=0.9)  # fmt: skip
    watch = SensorWatch(config, stall_s=1.0, vox_range_c=(25.0, 40.0))
    assert watch.frame(frame(0, 40.9), 0.0) == []  # within the margin
    got = watch.frame(frame(1, 41.1), 0.1)
    assert kinds(got) == [("alarm", "vox_range")]
    assert "VOx 41.10 C outside the fitted 25-40 C (margin 1)" == got[0]["condition"]
    assert watch.frame(frame(2, 35.0), 0.2) == []  # clear_s
    assert kinds(watch.frame(frame(3, 35.0), 0.8)) == [("clear", "vox_range")]
    assert watch.frame(frame(4, bad=0.6), 1.0) == []  # corrupt_s
    assert kinds(watch.frame(frame(5, bad=0.6), 1.5)) == [("alarm", "corrupt")]
    assert watch.frame(frame(6, bad=0.4), 1.6) == []  # a few bad pixels are not corrupt
    assert kinds(watch.frame(frame(7), 2.2)) == [("clear", "corrupt")]
    # the shutter closed on end for 2 s
    t = 3.0
    got = []
    while t < 5.5:
        got += watch.frame(frame(8, in_ffc=True), t)
        t += 0.1
    assert kinds(got) == [("alarm", "shutter")]
    assert got[0]["condition"].startswith("shutter closed for 2.")
    assert watch.raised == ["shutter"]
    assert kinds(watch.tick(6.0, age_s=1.2, in_ffc=False)) == [("alarm", "no_data")]
    assert watch.tick(6.1, age_s=1.3, in_ffc=False) == []


def test_a_shutter_that_closes_again_and_again() -> None:
    config = FailsafeConfig(shutter_window_s=2, shutter_max_share=0.5, clear_s=0.5)
    watch = SensorWatch(config, stall_s=1.0, vox_range_c=None)
    got = []
    for k in range(60):  # closed 0.9 s of every second, 10 frames a second
        got += watch.frame(frame(k, in_ffc=k % 10 != 0), 0.1 * k)
    assert kinds(got) == [("alarm", "shutter")]
    assert got[0]["condition"] == "shutter closed 90% of the last 1 s"  # 0.9 s of 1.0
    assert got[0]["frame"] == 10  # once the window is half full
    for k in range(60, 100):
        got += watch.frame(frame(k), 0.1 * k)
    assert kinds(got)[1:] == [("clear", "shutter")]


def test_frames_lost_while_the_shutter_is_open_do_not_make_it_a_fault() -> None:
    # closed 0.2 s of every second; of the open frames only one a second arrives (a busy
    # machine): two of every three frames are closed ones, but not two thirds of the time
    watch = SensorWatch(FailsafeConfig(shutter_window_s=2, shutter_max_share=0.5), 1.0, None)
    got = []
    for k in (k for k in range(60) if k % 10 in (0, 1, 3)):
        got += watch.frame(frame(k, in_ffc=k % 10 < 2), 0.1 * k)
    assert got == []


def test_no_data_waits_longer_while_the_shutter_closes_and_for_the_first_frame() -> None:
    watch = SensorWatch(FailsafeConfig(ffc_grace_s=2, startup_s=10), 3.0, None)
    assert watch.tick(0.0, age_s=4.0, in_ffc=True) == []
    assert watch.tick(0.0, age_s=9.0, in_ffc=False, first=True) == []
    assert kinds(watch.tick(0.0, age_s=5.1, in_ffc=True)) == [("alarm", "no_data")]


# -- the pre-trigger buffer ---------------------------------------------------------------------


@settings(max_examples=30, deadline=None)
@given(
    st.integers(1, 40),
    st.integers(1, 40),
    st.sampled_from(["<u2", "<u1"]),
    st.booleans(),
    st.integers(0, 2**31),
)
def test_a_packed_match_unpacks_bit_for_bit(
    h: int, w: int, dtype: str, ir: bool, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    depth = rng.integers(0, 65535, (h, w), dtype=np.uint16)
    thermal = rng.integers(0, 65535, (h + 1, w), dtype=np.uint16)
    pair = SimpleNamespace(
        depth=depth,
        thermal=thermal,
        depth_time_s=1.5,
        thermal_time_s=1.6,
        telemetry=Telemetry(3, 308.0, 300.0, FfcState.IN_PROGRESS),
        index=9,
        ir=rng.integers(0, 255, (h, w), dtype=np.uint8) if ir else None,
        thermal_preview=None,
    )
    m = match_of(pair)  # type: ignore[arg-type]
    back = PackedMatch.of(m).unpack()
    assert np.array_equal(back.pair.depth, depth) and back.pair.depth.dtype == np.uint16
    assert np.array_equal(back.pair.thermal, thermal)
    assert (back.pair.ir is None) == (not ir) and (
        not ir or np.array_equal(back.pair.ir, m.depth.ir)
    )
    assert back.pair.telemetry == pair.telemetry and back.pair.index == 9
    assert (back.depth.time_s, back.thermal.time_s) == (1.5, 1.6)


def test_the_pre_trigger_buffer_is_bounded_by_seconds_and_bytes() -> None:
    pairs = list(open_source("sim", frames=30))
    pre = PreTrigger(keep_s=1.0, max_bytes=10**9)
    for p in pairs:
        pre.add(match_of(p))
    kept = pre.snapshot()
    span = kept[-1].thermal_time_s - kept[0].thermal_time_s
    assert 0.85 <= span <= 1.0 and pre.evicted == 0
    one = kept[0].nbytes
    small = PreTrigger(keep_s=10.0, max_bytes=int(3.5 * one))
    for p in pairs:
        small.add(match_of(p))
    assert len(small.snapshot()) == 3 and small.nbytes <= 3.5 * one
    assert small.evicted == 27
    assert one < 0.6 * (pairs[0].depth.nbytes + pairs[0].thermal.nbytes)  # compressed


# -- the storage rule ---------------------------------------------------------------------------


def make_item(root: Path, kind: str, rig: str, started_s: float, name: str = "") -> Path:
    path = root / kind / rig / f"{stamp(started_s)}{name}"
    path.mkdir(parents=True)
    (path / "data").write_bytes(b"x" * 1000)
    return path


def test_retention_by_age_then_free_space_continuous_first(tmp_path: Path) -> None:
    now = 1_800_000_000.0
    day = 86400.0
    old_seg = make_item(tmp_path, "continuous", "a", now - 40 * day, ".zarr")
    seg1 = make_item(tmp_path, "continuous", "a", now - 2 * day, ".zarr")
    seg2 = make_item(tmp_path, "continuous", "b", now - 1 * day, ".zarr")
    busy = make_item(tmp_path, "continuous", "b", now - 3 * day, ".zarr")
    old_clip = make_item(tmp_path, "clips", "a", now - 31 * day, "-hot")
    clip1 = make_item(tmp_path, "clips", "a", now - 5 * day, "-hot")
    clip2 = make_item(tmp_path, "clips", "b", now - 4 * day, "-hot")
    free = {"bytes": 0}
    deleted: list[str] = []

    def free_bytes(path: Path) -> int:
        # each deletion frees 1 GB in this test
        gone = sum(not p.exists() for p in (seg1, seg2, clip1, clip2, old_seg, old_clip))
        return free["bytes"] + int(gone * 1e9)

    config = StorageConfig(path=tmp_path, retention_days=30, min_free_gb=4.5)
    rule = Retention(config, lambda: {busy}, deleted.append, free_bytes)
    assert rule.sweep(now) is None
    # by age: both old ones (2 GB); by space: the oldest continuous, then the next ...
    assert not old_seg.exists() and not old_clip.exists()
    assert not seg1.exists() and not seg2.exists() and not clip1.exists()
    assert clip2.exists() and busy.exists()  # 5 GB free: enough; being written: kept
    assert deleted == [f"a/{old_clip.name}", f"a/{clip1.name}"]
    assert rule.deleted == {"continuous": 3, "clips": 2, "reports": 0}
    free["bytes"] = -(10**10)  # a disk that fills anyway
    line = rule.sweep(now)
    assert line is not None
    assert "less than min_free_gb 4.5, and no recording, clip or report left" in line
    assert not clip2.exists() and busy.exists()


def test_a_continuous_segment_that_fails_as_it_closes_pauses_the_next(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # a full disk seen only when the segment closes (its writer thread was behind): told, and
    # no segment is started for RETRY_S, as when add sees it (not one segment every segment_s)
    started: list[Path] = []
    behind = threading.Event()  # the writer thread is behind until set

    class Writer:
        def __init__(self, path: Path, *args: Any, **kwargs: Any) -> None:
            started.append(path)

    class FullDisk:
        def __init__(self, writer: Writer, block: bool) -> None:
            pass

        def add(self, event: Any) -> None:
            pass

        def close(self, attrs: Any) -> None:
            behind.wait(60)
            raise OSError(28, "No space left on device")

    monkeypatch.setattr(storage, "RecordingWriter", Writer)
    monkeypatch.setattr(storage, "Recorder", FullDisk)
    faults: list[str] = []
    recorder = ContinuousRecorder(tmp_path, segment_s=0.0, on_fault=faults.append)
    source = SimpleNamespace(calibration=None, settings=dict, name="sim", device_depth=False)
    recorder.open(SimpleNamespace(source=source, calibration=None, provenance={}))
    recorder.add("pair")
    recorder.add("pair")  # the first segment's time is up: closed on its thread; a second
    assert len(started) == 2 and not faults
    behind.set()
    recorder.join()
    assert len(faults) == 1
    assert "not closed cleanly ([Errno 28] No space left on device)" in faults[0]
    for _ in range(5):
        recorder.add("pair")  # the second closes (told), and none is started
        recorder.join()
    assert len(started) == 2 and len(faults) == 2


# -- a recording at its recorded pace -----------------------------------------------------------


def test_a_recording_replays_at_its_pace_on_unix_time_and_again(tmp_path: Path) -> None:
    take = tmp_path / "take.zarr"
    record_session(open_source("sim", frames=6), take)
    paced = PacedSource(open_source(f"recording:{take}"), replay=True, index_from=100)
    t0 = time.time()
    got = []
    for p in paced:
        got.append((p.index, p.thermal_time_s, time.time()))
        if len(got) == 14:
            break
    paced.close()
    indices = [g[0] for g in got]
    assert indices == list(range(100, 114))  # numbered on, again and again
    times = np.array([g[1] for g in got])
    released = np.array([g[2] for g in got])
    assert t0 - 0.01 <= times[0] <= released[0]  # Unix time, from when it was started
    assert np.allclose(np.diff(times), 1 / 8.7, atol=0.02)  # the recorded pace, passes joined
    # released when a camera would send it: never before its time (how late a busy machine
    # makes it is the bench's to measure, and past LATE_S it would be dropped, counted below)
    assert np.all(released >= times - 0.01)
    assert paced.dropped == 0


def test_a_paced_pair_reached_late_is_dropped(tmp_path: Path) -> None:
    take = tmp_path / "take.zarr"
    record_session(open_source("sim", frames=12), take)
    paced = PacedSource(open_source(f"recording:{take}"), replay=True)
    seen = []
    for p in paced:
        seen.append(p.index)
        if len(seen) == 1:
            time.sleep(1.3)  # a consumer that falls behind by more than LATE_S
        if len(seen) == 4:
            break
    paced.close()
    assert paced.dropped >= 1 and seen[0] == 0 and seen[1] > 1


# -- systemd ------------------------------------------------------------------------------------


def test_notify_sends_datagrams_to_the_notify_socket(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delenv("NOTIFY_SOCKET", raising=False)
    assert notify("READY=1") is False  # not under systemd
    path = tmp_path / "notify"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as server:
        server.bind(str(path))
        monkeypatch.setenv("NOTIFY_SOCKET", str(path))
        assert notify("READY=1", "STATUS=watching 2 rigs") is True
        assert server.recv(4096) == b"READY=1\nSTATUS=watching 2 rigs"
    monkeypatch.setenv("WATCHDOG_USEC", "30000000")
    monkeypatch.setenv("WATCHDOG_PID", str(os.getpid()))
    assert watchdog_interval_s() == 15.0
    monkeypatch.setenv("WATCHDOG_PID", "1")
    assert watchdog_interval_s() is None  # another process's watchdog


def test_notify_never_waits_for_a_reader_that_does_not_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "notify"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as server:
        server.bind(str(path))
        monkeypatch.setenv("NOTIFY_SOCKET", str(path))
        sent = [notify("WATCHDOG=1") for _ in range(2000)]  # far more than its queue holds
        assert sent[0] is True and sent[-1] is False  # dropped, not waited on
        assert server.recv(64) == b"WATCHDOG=1"


def test_notify_reaches_an_abstract_socket(monkeypatch: pytest.MonkeyPatch) -> None:
    name = f"thermodepth-test-{os.getpid()}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as server:
        server.bind("\0" + name)
        monkeypatch.setenv("NOTIFY_SOCKET", "@" + name)
        assert notify("WATCHDOG=1")
        assert server.recv(64) == b"WATCHDOG=1"


# -- the log ------------------------------------------------------------------------------------


def test_the_logs_levels_come_from_the_config_per_rig(tmp_path: Path) -> None:
    import logging

    from thermodepth.monitor import Monitor

    path = monitor_config(
        tmp_path,
        [{"name": "a", "source": "sim"}, {"name": "b", "source": "sim"}],
        http={"listen": None},
        log={"level": "warning", "rigs": {"a": "debug"}},
    )
    from thermodepth.monitor.logs import apply_levels

    Monitor(load_config(path)).store.close()  # made, not started: levels set
    try:
        assert logging.getLogger("thermodepth.monitor").level == logging.WARNING
        assert logging.getLogger("thermodepth.monitor.rig.a").getEffectiveLevel() == logging.DEBUG
        assert logging.getLogger("thermodepth.monitor.rig.b").getEffectiveLevel() == logging.WARNING
    finally:
        apply_levels()  # as the next monitor of this process would
    bad = monitor_config(
        tmp_path, [{"name": "a", "source": "sim"}], log={"level": "loud", "rigs": {"z": "info"}}
    )
    with pytest.raises(InputError) as info:
        load_config(bad)
    assert "log.level: Input should be 'debug', 'info', 'warning' or 'error'" in str(info.value)
    monitor_config(tmp_path, [{"name": "a", "source": "sim"}], log={"rigs": {"z": "info"}})
    with pytest.raises(InputError, match=r"log.rigs.z: no rig of that name \(a\)"):
        load_config(tmp_path / "monitor.yaml")


def test_a_log_line_is_one_line_stamped_or_with_the_journals_priority(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    import io
    import logging

    from thermodepth.monitor.logs import install_handler, rig_logger

    for journal, want in ((None, r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}\+00:00 press7: stalled$"),
                          ("8:1234", r"^<4>press7: stalled$")):  # fmt: skip
        if journal is None:
            monkeypatch.delenv("JOURNAL_STREAM", raising=False)
        else:
            monkeypatch.setenv("JOURNAL_STREAM", journal)  # systemd sets it for its journal
        out = io.StringIO()
        handler = install_handler(out)
        try:
            rig_logger("press7").warning("%s: %s", "press7", "stalled")
            rig_logger("press7").debug("not at info")
        finally:
            logging.getLogger("thermodepth.monitor").removeHandler(handler)
        lines = out.getvalue().splitlines()
        assert len(lines) == 1 and re.match(want, lines[0]), lines
    out = io.StringIO()
    handler = install_handler(out)
    try:
        try:
            raise ValueError("boom")
        except ValueError:
            logging.getLogger("thermodepth.monitor.workers").error("clock failed", exc_info=True)
    finally:
        logging.getLogger("thermodepth.monitor").removeHandler(handler)
    assert out.getvalue().splitlines()[0].endswith("<3>clock failed")
    assert "ValueError: boom" in out.getvalue()  # its traceback on the lines after


def test_a_server_s_port_is_checked_before_it_starts_ipv6_too() -> None:
    # the outputs' servers (Modbus, OPC UA, RTSP) check their port first: one line when taken
    from thermodepth.monitor.outputs.base import check_port

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(InputError, match=r"^modbus.listen: x: cannot listen \(.+\)$"):
            check_port("127.0.0.1", port, "modbus.listen: x")
    try:
        with socket.socket(socket.AF_INET6) as probe:
            probe.bind(("::1", 0))
            free = probe.getsockname()[1]
    except OSError:
        pytest.skip("no IPv6 loopback here")
    check_port("::1", free, "rtsp.listen: [::1]")  # an IPv6 host is bound as one
