"""`thermodepth batch` on dask.distributed: the same files as `run` (alarms across range
boundaries included), a summary, a worker killed mid-task, --resume, bad input."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import signal
from pathlib import Path

import pytest
from typer.testing import CliRunner

pytest.importorskip("distributed", reason="batch needs the distributed extra (dask)")

from distributed import Client, LocalCluster
from distributed.diagnostics.plugin import WorkerPlugin

from chip_settings import HOT_CHIP, chip_settings
from thermodepth.app.batch import (
    BatchOptions,
    PipelineSpec,
    RangeTask,
    batch,
    measure_range,
    plan,
)
from thermodepth.app.run import RunOptions, run
from thermodepth.cli import app
from thermodepth.errors import FieldError, InputError
from thermodepth.io.measurements import FILES, FrameLines
from thermodepth.io.recording import Recording
from thermodepth.pipeline import Pipeline, Settings
from thermodepth.session import record_session
from thermodepth.sim import Rig, camera_pose, plate_scene
from thermodepth.sources.sim import SimSource


@pytest.fixture(scope="module")
def rig_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("batch")
    # ranges of 7 pairs cut through its counts, and through an on-delay in seconds (the
    # warm-up reaches back 0.35 s)
    chip_settings(d, "  - {name: warm, above_c: 67.45, for_s: 0.35}\n", 3)
    for name, n in (("a", 40), ("b", 25)):
        rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.0), seed=len(name) + n)
        record_session(SimSource(rig), d / f"{name}.zarr", frames=n)
        run(RunOptions(f"recording:{d / f'{name}.zarr'}", d / "s.yaml", out_dir=d / f"run_{name}"))
    return {"dir": d, "settings": d / "s.yaml"}


@pytest.fixture(scope="module")
def cluster() -> LocalCluster:
    saved = dict(os.environ)  # the nannies set their workers' variables in ours
    with LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        host="127.0.0.1",
        dashboard_address="127.0.0.1:0",
        silence_logs=50,
    ) as c:
        yield c
    os.environ.clear()
    os.environ.update(saved)


def same_as_run(d: Path, out: Path, name: str) -> None:
    for f in FILES:
        assert (out / name / f).read_bytes() == (d / f"run_{name}" / f).read_bytes(), f


def options(rig_files: dict[str, Path], out: Path, *names: str, **kw: object) -> BatchOptions:
    d = rig_files["dir"]
    recs = tuple(str(d / f"{n}.zarr") for n in names or ("a", "b"))
    return BatchOptions(recs, out, rig_files["settings"], **kw)  # type: ignore[arg-type]


def test_outputs_are_those_of_run_byte_for_byte(rig_files: dict[str, Path], tmp_path: Path) -> None:
    d = rig_files["dir"]
    assert (d / "run_a" / "alarms.jsonl").read_text().count('"alarm"') >= 2  # a real test
    seen: list[tuple[str, int | None, int]] = []

    class Recorder:
        def task(self, description, total):  # type: ignore[no-untyped-def]
            from contextlib import contextmanager

            @contextmanager
            def cm():  # type: ignore[no-untyped-def]
                def advance(n=1, /, description=None):  # type: ignore[no-untyped-def]
                    seen.append(("advance", None, n))

                seen.append((description, total, 0))
                yield advance

            return cm()

    said: list[str] = []
    environ = dict(os.environ)
    result = batch(
        options(rig_files, tmp_path / "out", workers=2, range_pairs=7),
        Recorder(),
        None,
        said.append,
    )
    assert dict(os.environ) == environ  # the workers' variables stay theirs
    for name in ("a", "b"):
        same_as_run(d, tmp_path / "out", name)
    assert sorted(result.measured) == ["a", "b"] and result.pairs == 65 and not result.failed
    assert said and said[0].startswith("dask dashboard: http://127.0.0.1:")
    assert seen[0] == ("measuring 2 recordings", 65, 0)
    assert sum(n for what, _, n in seen if what == "advance") == 65  # every pair, once
    rows = read_csv(tmp_path / "out" / "summary.csv")
    assert [r["recording"] for r in rows] == ["a", "b"]
    csv_says_what_parquet_says(tmp_path / "out")
    for row in rows:
        events = read_jsonl(d / f"run_{row['recording']}" / FILES[1])
        frames = read_jsonl(d / f"run_{row['recording']}" / FILES[0])
        hottest = max(f["hotspots"][0]["max_c"] for f in frames if f["hotspots"])
        assert row["status"] == "ok" and int(row["frames"]) == len(frames)
        assert int(row["alarms:hot"]) == sum(
            e["event"] == "alarm" and e["rule"] == "hot" for e in events
        )
        assert float(row["hottest_c"]) == hottest
    import pyarrow.parquet as pq

    table = pq.read_table(tmp_path / "out" / "summary.parquet").to_pylist()
    assert [t["frames"] for t in table] == [40, 25] and table[0]["hottest_c"] == hottest_of(d, "a")
    assert (
        "![hottest reading over time](summary.png)" in (tmp_path / "out" / "summary.md").read_text()
    )
    assert (tmp_path / "out" / "summary.png").stat().st_size > 10_000


def read_jsonl(path: Path) -> list[dict]:  # type: ignore[type-arg]
    return [json.loads(x) for x in path.read_text(encoding="utf-8").splitlines()]


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, encoding="utf-8", newline="") as f:
        return list(csv.DictReader(f))


def csv_says_what_parquet_says(out: Path) -> None:
    """summary.csv read by column name holds, cell for cell, summary.parquet's values (an
    empty cell: none)."""
    import pyarrow.parquet as pq

    table = pq.read_table(out / "summary.parquet")
    rows = read_csv(out / "summary.csv")
    assert list(rows[0]) == table.column_names
    assert rows == [
        {k: "" if v is None else str(v) for k, v in row.items()} for row in table.to_pylist()
    ]


def hottest_of(d: Path, name: str) -> float:
    frames = read_jsonl(d / f"run_{name}" / FILES[0])
    return max(f["hotspots"][0]["max_c"] for f in frames if f["hotspots"])


def test_every_range_start_rebuilds_the_alarm_counts(rig_files: dict[str, Path]) -> None:
    # without dask: a range starting at any pair gives the lines of the whole run there
    d = rig_files["dir"]
    settings = Settings.load(rig_files["settings"])
    spec = PipelineSpec(settings, None, None)
    whole = (d / "run_a" / "measurements.jsonl").read_text().splitlines(keepends=True)
    alarms = (d / "run_a" / "alarms.jsonl").read_text().splitlines(keepends=True)
    got_alarms = []
    for start in range(0, 40, 3):
        part = measure_range(spec, RangeTask("a", str(d / "a.zarr"), start, min(start + 3, 40)))
        assert part.error is None
        assert [f.frame for f in part.frames] == whole[start : start + 3], start
        got_alarms += [a for f in part.frames for a in f.alarms]
    assert got_alarms == alarms


def test_tasks_of_recordings_with_one_calibration_share_its_registration(
    rig_files: dict[str, Path],
) -> None:
    d = rig_files["dir"]
    spec = PipelineSpec(Settings.load(rig_files["settings"]), None, None)
    a, b = (Recording(d / f"{n}.zarr").calibration for n in ("a", "b"))
    assert a is not b and a is not None and b is not None  # each opening makes its own
    first, second = spec.pipeline(a), spec.pipeline(b)
    assert first.registration is second.registration
    assert first.calibration.to_dict() == a.to_dict()


class KillOnce(WorkerPlugin):
    """Makes the first worker that runs pairs 7-13 of recording a die there (SIGKILL), once."""

    def __init__(self, marker: str) -> None:
        self.marker = marker

    def setup(self, worker: object) -> None:
        import thermodepth.app.batch as b

        self.original = original = b.measure_range
        marker = Path(self.marker)

        def measure_range(spec, task):  # type: ignore[no-untyped-def]
            if task.name == "a" and task.start == 7 and not marker.exists():
                marker.write_text(str(os.getpid()))
                os.kill(os.getpid(), signal.SIGKILL)
            return original(spec, task)

        b.measure_range = measure_range

    def teardown(self, worker: object) -> None:
        import thermodepth.app.batch as b

        b.measure_range = self.original


def test_a_worker_killed_mid_task_is_retried(
    rig_files: dict[str, Path], cluster: LocalCluster, tmp_path: Path
) -> None:
    marker = tmp_path / "killed"
    with Client(cluster) as client:
        client.register_plugin(KillOnce(str(marker)), name="kill-once")
        result = batch(
            options(rig_files, tmp_path / "out", scheduler=cluster.scheduler_address, range_pairs=7)
        )
        client.unregister_worker_plugin("kill-once")
    assert marker.exists()  # a worker died in the middle of a task
    assert sorted(result.measured) == ["a", "b"] and not result.failed
    for name in ("a", "b"):
        same_as_run(rig_files["dir"], tmp_path / "out", name)


def test_bad_recordings_fail_alone_in_one_line(
    rig_files: dict[str, Path], cluster: LocalCluster, tmp_path: Path
) -> None:
    d = rig_files["dir"]
    broken = tmp_path / "broken.zarr"
    shutil.copytree(d / "b.zarr", broken)
    (broken / "zarr.json").write_text("{ not json", encoding="utf-8")
    recs = (str(d / "a.zarr"), str(broken), str(tmp_path / "gone.zarr"))
    lines: list[str] = []
    result = batch(
        BatchOptions(
            recs, tmp_path / "out", rig_files["settings"], scheduler=cluster.scheduler_address
        ),
        warn=lines.append,
    )
    assert result.measured == ["a"] and set(result.failed) == {"broken", "gone"}
    assert all("\n" not in m for m in result.failed.values())
    assert result.failed["gone"] == f"{tmp_path / 'gone.zarr'}: no such recording"
    assert result.failed["broken"].startswith(f"{broken}: not a readable Zarr v3 store")
    same_as_run(d, tmp_path / "out", "a")
    rows = {r["recording"]: r for r in read_csv(tmp_path / "out" / "summary.csv")}
    assert rows["gone"]["status"].startswith("failed: ") and rows["a"]["status"] == "ok"
    csv_says_what_parquet_says(tmp_path / "out")


def test_resume_skips_complete_and_redoes_partial(
    rig_files: dict[str, Path], cluster: LocalCluster, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    first = options(rig_files, out, scheduler=cluster.scheduler_address)
    batch(first)
    stamp = (out / "a" / FILES[0]).stat().st_mtime_ns
    shutil.rmtree(out / "b")
    (out / "b.partial").mkdir()
    (out / "b.partial" / FILES[0]).write_text('{"frame": 0', encoding="utf-8")  # cut short
    with pytest.raises(FieldError, match="holds a batch's results: --resume completes them"):
        batch(first)
    again = batch(options(rig_files, out, scheduler=cluster.scheduler_address, resume=True))
    assert again.complete == ["a"] and again.measured == ["b"]
    assert (out / "a" / FILES[0]).stat().st_mtime_ns == stamp  # not written again
    assert not (out / "b.partial").exists()
    for name in ("a", "b"):
        same_as_run(rig_files["dir"], out, name)
    # other settings: their results are not this batch's
    other = tmp_path / "other.yaml"
    other.write_text(HOT_CHIP.format(for_frames=3).replace("67.48", "67.5"), encoding="utf-8")
    changed = BatchOptions(first.recordings, out, other, resume=True)
    with pytest.raises(FieldError, match="holds results of other settings"):
        batch(changed)


def test_file_urls(rig_files: dict[str, Path], cluster: LocalCluster, tmp_path: Path) -> None:
    url = (rig_files["dir"] / "a.zarr").as_uri()
    assert url.startswith("file:///")
    result = batch(
        BatchOptions(
            (url,), tmp_path / "out", rig_files["settings"], scheduler=cluster.scheduler_address
        )
    )
    assert result.measured == ["a"]
    same_as_run(rig_files["dir"], tmp_path / "out", "a")


def test_refused_before_any_task(rig_files: dict[str, Path], tmp_path: Path) -> None:
    d = rig_files["dir"]
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine", encoding="utf-8")
    for opts, message in [
        (
            options(rig_files, foreign, overwrite=True),
            re.escape("holds other files (notes.txt, ...)"),
        ),
        (options(rig_files, tmp_path / "x", workers=2, scheduler="tcp://h:1"), "not both"),
        (
            BatchOptions((str(d / "a.zarr"), str(tmp_path / "a.zarr")), tmp_path / "y"),
            "both write a/",
        ),
    ]:
        with pytest.raises((FieldError, InputError), match=message):
            batch(opts)
    torn = tmp_path / "torn"
    torn.mkdir()
    (torn / "batch.json").write_text("{ not json", encoding="utf-8")
    with pytest.raises(FieldError, match=r"torn/batch\.json is unreadable \(JSONDecodeError: "):
        batch(options(rig_files, torn, resume=True))
    bad = tmp_path / "bad.yaml"
    bad.write_text("alarms:\n  - name: hot\n    above_c: hot\n", encoding="utf-8")
    bad_opts = options(rig_files, tmp_path / "z")
    with pytest.raises(InputError, match=r"bad\.yaml: alarms\.0\.above_c"):
        batch(BatchOptions(bad_opts.recordings, tmp_path / "z", bad))
    assert not (tmp_path / "z").exists()  # nothing made before the settings were valid
    with pytest.raises(
        FieldError, match=r"^scheduler: no dask scheduler answers at tcp://127.0.0.1:9 "
    ):
        batch(options(rig_files, tmp_path / "w", scheduler="tcp://127.0.0.1:9"))


def test_overwrite_replaces_an_earlier_batch(
    rig_files: dict[str, Path], cluster: LocalCluster, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    batch(options(rig_files, out, "a", "b", scheduler=cluster.scheduler_address))
    result = batch(
        options(rig_files, out, "a", scheduler=cluster.scheduler_address, overwrite=True)
    )
    assert result.measured == ["a"] and not (out / "b").exists()
    same_as_run(rig_files["dir"], out, "a")


def test_cli_exit_code_and_lines(rig_files: dict[str, Path], tmp_path: Path) -> None:
    d = rig_files["dir"]
    runner = CliRunner()
    res = runner.invoke(
        app,
        [
            "batch",
            str(d / "a.zarr"),
            str(tmp_path / "gone.zarr"),
            "-o",
            str(tmp_path / "out"),
            "--settings",
            str(rig_files["settings"]),
            "--workers",
            "1",
        ],
    )
    assert res.exit_code == 2
    assert "dask dashboard: http://127.0.0.1:" in res.output
    assert "1 recordings measured (40 pairs" in res.output
    assert "1 of 2 recordings could not be measured" in res.output
    same_as_run(d, tmp_path / "out", "a")
    res = runner.invoke(app, ["batch", "-o", str(tmp_path / "o2")])
    assert res.exit_code == 2


def test_frame_lines_are_what_the_writer_writes(tmp_path: Path) -> None:
    rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.0))
    pipe = Pipeline(Settings.model_validate({"hotspots": {"threshold_c": 50}}), rig.calibration)
    fused = next(f for f in map(pipe.process, rig.frames(5)) if not f.in_ffc)
    from thermodepth.io.measurements import MeasurementWriter

    with MeasurementWriter(tmp_path) as w:
        w.write(fused)
    lines = FrameLines.of(fused)
    assert lines.hotspots
    assert read_csv(tmp_path / FILES[2]) == [
        {k: str(v) for k, v in row.items()} for row in lines.hotspots
    ]
    assert (tmp_path / FILES[0]).read_text() == lines.frame


def test_rules_that_remember_everything_make_one_task_per_recording(
    rig_files: dict[str, Path],
) -> None:
    d = rig_files["dir"]
    for rule, whole in (
        ("{name: r, above_c: 60, for_s: 2}", False),
        ("{name: r, above_c: 60, latch: true}", True),
        ("{name: r, above_c: 60, clear_below_c: 55}", True),
        ("{name: r, above_c: 60, clear_for_s: 1}", True),
    ):
        (d / "r.yaml").write_text(f"alarms: [{rule}]\n")
        spec = PipelineSpec(Settings.load(d / "r.yaml"), None, None)
        job = plan("a", str(d / "a.zarr"), spec, 7, lambda line: None)
        assert spec.whole_recordings == whole and (len(job.tasks) == 1) == whole, rule
