"""The rerun viewer sink (saved to .rrd and read back with rerun's own reader), `view`, and
`run --snapshots`."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

from chip_settings import chip_settings
from thermodepth.app.run import RunOptions, run
from thermodepth.cli import app
from thermodepth.errors import FieldError, ThermodepthError
from thermodepth.pipeline import Pipeline, Settings, ViewerSettings
from thermodepth.plotting import distinct_styles
from thermodepth.sim import Rig, camera_pose, plate_scene
from thermodepth.sinks.viewer import INSTALL, ViewerSink, colour_scale

EXTRA = """\
rois:
  - name: panel
    rect: [400, 200, 880, 520]
viewer:
  max_points: 20000
"""


@pytest.fixture()
def settings(tmp_path: Path) -> Path:
    return chip_settings(tmp_path, EXTRA)


WANTED = (
    "/world/cloud",
    "/world/depth",
    "/world/thermal",
    "/images/depth/temperature",
    "/images/thermal/counts",
    "/world/hotspots",
    "/images/depth/rois",
    "/plots/hottest_c",
    "/plots/vox_c",
    "/plots/roi/panel/mean_c",
    "/alarms",
    "/legend/colour_scale",
)


def per_frame(rrd: Path, entity: str, component: str) -> dict[int, object]:
    from rerun.chunk import RrdReader

    out: dict[int, object] = {}
    for chunk in RrdReader(str(rrd)).stream().filter(content=entity, is_static=False):
        batch = chunk.to_record_batch()
        if component in batch.schema.names:
            frames = batch.column("frame").to_pylist()
            out.update(zip(frames, batch.column(component).to_pylist(), strict=True))
    return dict(sorted(out.items()))


def test_a_saved_view_holds_what_was_measured(settings: Path, tmp_path: Path) -> None:
    pytest.importorskip("rerun", reason="the viewer needs the viewer extra (rerun-sdk)")
    from rerun.chunk import RrdReader

    rrd = tmp_path / "run.rrd"
    result = run(RunOptions("sim", settings, 10, tmp_path / "out", viewer_save=rrd))
    assert "viewer: 10 frames logged, saved to" in " ".join(result.outputs)  # sim: every frame
    entities = set(RrdReader(str(rrd)).store().schema().entity_paths())
    for e in WANTED:
        assert e in entities, e
    frames = [
        json.loads(x) for x in (tmp_path / "out" / "measurements.jsonl").read_text().splitlines()
    ]
    points = per_frame(rrd, "/world/cloud", "Points3D:positions")
    assert set(points) == {f["frame"] for f in frames}
    assert all(15_000 < len(p) <= 20_000 for p in points.values())  # strided to max_points
    hottest = per_frame(rrd, "/plots/hottest_c", "Scalars:scalars")
    labels = per_frame(rrd, "/world/hotspots", "Boxes3D:labels")
    centres = per_frame(rrd, "/world/hotspots", "Boxes3D:centers")
    rois = per_frame(rrd, "/plots/roi/panel/max_c", "Scalars:scalars")
    hot_frames = [f for f in frames if f["hotspots"]]
    assert len(hot_frames) >= 5
    for f in hot_frames:
        h = f["hotspots"][0]
        assert hottest[f["frame"]] == [pytest.approx(h["max_c"], abs=1e-4)]
        assert labels[f["frame"]][0].startswith(f"{h['max_c']:.1f} C, ")  # type: ignore[index]
        assert np.allclose(centres[f["frame"]][0], h["centroid_m"], atol=1e-5)  # type: ignore[index]
        assert rois[f["frame"]] == [pytest.approx(f["rois"][0]["max_c"], abs=1e-4)]
    events = (tmp_path / "out" / "alarms.jsonl").read_text().splitlines()
    logged = per_frame(rrd, "/alarms", "TextLog:text")
    assert len(events) >= 1 and len(logged) == len({json.loads(e)["frame"] for e in events})


def test_live_sources_are_logged_at_a_bounded_rate() -> None:
    pytest.importorskip("rerun", reason="the viewer needs the viewer extra (rerun-sdk)")
    rig = Rig(plate_scene(chip_temp_c=70.0), camera_pose(1.0))
    pipe = Pipeline(Settings(), rig.calibration)
    fused = [pipe.process(p) for p in rig.frames(4)]
    sink = ViewerSink("save", str(Path("/tmp") / "never-written.rrd"), ViewerSettings(max_hz=0.5))
    sink.rec = SimpleNamespace(set_time=lambda *a, **k: None, log=lambda *a, **k: None)
    for f in fused:  # as fast as the pipeline gives them: one frame in the first 2 s
        sink.frame(f)
    assert (sink.logged, sink.skipped) == (1, 3)
    assert "3 skipped to keep to 0.5 frames/s" in sink.summary()


def test_cloud_colours_grey_where_there_is_no_temperature() -> None:
    rgb = colour_scale(np.array([np.nan, 15.0, 80.0, 200.0]), (15.0, 80.0))
    assert rgb[0].tolist() == [110, 110, 110]
    assert rgb[2].tolist() == rgb[3].tolist()  # clipped at the top of the fixed scale
    assert rgb[1].sum() < rgb[2].sum()


def test_without_rerun_or_a_display_one_line(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(FieldError, match="no display to open a viewer on"):
        ViewerSink("spawn").check()
    monkeypatch.setitem(sys.modules, "rerun", None)  # as if rerun-sdk were not installed
    with pytest.raises(ThermodepthError) as info:
        ViewerSink("spawn").check()
    assert str(info.value) == INSTALL


def test_view_and_option_checks(settings: Path, tmp_path: Path) -> None:
    pytest.importorskip("rerun", reason="the viewer needs the viewer extra (rerun-sdk)")
    runner = CliRunner()
    rec = tmp_path / "r.zarr"
    assert (
        runner.invoke(app, ["record", "-s", "sim", "-o", str(rec), "--frames", "4"]).exit_code == 0
    )
    res = runner.invoke(
        app,
        ["view", str(rec), "--settings", str(settings), "--viewer-save", str(tmp_path / "v.rrd")],
    )
    assert res.exit_code == 0, res.output
    assert "viewer: 4 frames logged, saved to" in res.output
    assert len(per_frame(tmp_path / "v.rrd", "/world/cloud", "Points3D:positions")) == 4
    res = runner.invoke(app, ["run", "--viewer", "--viewer-save", str(tmp_path / "x.rrd")])
    assert (
        res.exit_code == 2
        and "--viewer: one of --viewer, --viewer-save, --viewer-connect" in res.output
    )
    res = runner.invoke(app, ["run", "--frames", "2", "--viewer-save", str(tmp_path / "x.txt")])
    assert (
        res.exit_code == 2
        and "--viewer-save: " in res.output
        and "expected a .rrd file" in res.output
    )


def test_snapshots_every_n_frames_and_at_alarms(settings: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = run(RunOptions("sim", settings, 14, out, snapshots=5))
    pngs = sorted(p.name for p in (out / "snapshots").glob("*.png"))
    events = [json.loads(x) for x in (out / "alarms.jsonl").read_text().splitlines()]
    alarm_frames = {e["frame"] for e in events if e["event"] == "alarm"}
    expected = {f"frame_{i:06d}.png" for i in {5, 10} | alarm_frames}  # 0: the shutter
    assert set(pngs) == expected and alarm_frames
    assert {p.with_suffix(".ply").name for p in (out / "snapshots").glob("*.png")} == {
        p.name for p in (out / "snapshots").glob("*.ply")
    }
    line = next(x for x in result.outputs if " snapshots (" in x)
    assert f"({len(alarm_frames)} at alarms" in line and "20-70 C" in line  # one scale for all
    with pytest.raises(FieldError, match="give --out"):
        run(RunOptions("sim", settings, 2, snapshots=5))


def test_figure_styles_tell_five_lines_apart() -> None:
    styles = distinct_styles(5)
    assert len({c for c, _ in styles}) == 5 and len({m for _, m in styles}) == 5
