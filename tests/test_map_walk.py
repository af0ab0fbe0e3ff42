"""``thermodepth map`` end to end on a short simulated walk round the machine: the model's
files, its geometry and temperatures against the walk's own truth, the trajectory from depth
odometry and from a TUM file, and bad options as one line. (The full walks, both scenes, are
measured by ``bench/bench_map.py``.)"""

from __future__ import annotations

import csv
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

pytest.importorskip("skimage", reason="the map needs the map extra (scikit-image)")
pytest.importorskip("trimesh", reason="the map's model.glb needs the map extra (trimesh)")

from thermodepth.app.map import MapOptions, build_map
from thermodepth.cli import app
from thermodepth.io.folder import write_folder
from thermodepth.io.model import read_model_ply
from thermodepth.io.recording import Recording
from thermodepth.sim.walk_truth import read_walk_truth
from thermodepth.sim.walkaround import simulate_walkaround
from thermodepth.trajectory import Trajectory

runner = CliRunner()
WALK_S = 1.5


@pytest.fixture(scope="module")
def walk(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("walk") / "walk.zarr"
    return simulate_walkaround(out, "machine", WALK_S, seed=0, depth="640x480")


@pytest.fixture(scope="module")
def settings(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("settings") / "settings.yaml"
    path.write_text("radiometry:\n  ambient_temp_c: 22.0\n")  # the machine's hall, as measured
    return path


@pytest.fixture(scope="module")
def mapped(walk: Path, settings: Path, tmp_path_factory: pytest.TempPathFactory) -> dict:
    out = tmp_path_factory.mktemp("model") / "model"
    result = runner.invoke(
        app, ["map", str(walk), "-o", str(out), "--settings", str(settings), "--voxel-m", "0.02"]
    )
    assert result.exit_code == 0, result.output
    assert "model of" in result.output and "against the truth" in result.output
    return {"out": out, "report": json.loads((out / "map_report.json").read_text()), "walk": walk}


def test_the_model_of_a_walk_matches_its_truth(mapped: dict) -> None:
    report = mapped["report"]
    truth = report["against_truth"]
    # odometry over every other depth frame (15 of 30 fps): millimetres (measured 0.6 mm)
    assert truth["trajectory"]["rmse_m"] < 0.01
    # 2 cm voxels from 640x480 depth out to 3 m: 4 mm from the surface on average, 97 %
    # within 2 cm (measured)
    assert truth["geometry"]["accuracy_m"] < 0.008
    assert truth["geometry"]["precision"] > 0.9
    t = truth["temperature"]
    assert t["vertices"] > 1000
    assert t["fused"]["mae_c"] < 0.6
    assert t["fused"]["p95_c"] < 2.0
    rec = Recording(mapped["walk"])
    assert report["trajectory"]["poses"] == rec.n_depth // 2 + 1 > 20  # not the pairs' only
    assert rec.n_depth > report["walk"]["depth_frames"] > report["trajectory"]["poses"]
    assert report["walk"]["views"] == report["walk"]["pairs"] == rec.n_pairs > 10


def test_the_model_files_hold_what_the_report_says(mapped: dict) -> None:
    out, report = mapped["out"], mapped["report"]
    for name in report["files"]:
        assert (out / name).is_file(), name
    ply = read_model_ply(out / "mesh.ply")
    assert len(ply["vertices"]) == report["mesh"]["vertices"]
    has = np.isfinite(ply["temperature"])
    assert has.mean() == pytest.approx(report["mesh"]["with_temperature"], abs=1e-3)
    # trusted views only where there is a temperature; a spread needs samples
    assert np.all(ply["views"][has] >= 1) and np.all(ply["views"][~has] == 0)
    scale = report["temperature_scale"]
    assert scale["min_c"] < 23.0 < scale["max_c"]  # the hall at 22 C is in the picture
    assert report["hotspots"]  # the machine's hot parts: the table below says something
    with open(out / "hotspots.csv", newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(report["hotspots"])
    for rank, (row, spot) in enumerate(zip(rows, report["hotspots"], strict=True), 1):
        assert int(row["rank"]) == rank and int(row["vertices"]) == spot["vertices"]
        assert int(row["peak_views"]) == spot["peak_views"]
        for name in ("peak_c", "fused_peak_c", "mean_c", "area_cm2", "extent_m"):
            assert float(row[name]) == pytest.approx(spot[name], nan_ok=True), name
        for i, axis in enumerate("xyz"):
            assert float(row[f"centre_{axis}_m"]) == spot["centre_m"][i]
            assert float(row[f"peak_{axis}_m"]) == spot["peak_m"][i]
    trajectory = Trajectory.load_tum(out / "trajectory.tum")
    assert len(trajectory) == report["trajectory"]["poses"]


def test_a_given_trajectory_is_used_as_it_is_and_a_folder_maps_as_its_recording(
    walk: Path, settings: Path, tmp_path: Path
) -> None:
    truth = read_walk_truth(walk)
    assert truth is not None
    tum = truth.trajectory.save_tum(tmp_path / "walk.tum")
    options = MapOptions(str(walk), tmp_path / "m", settings, tum, voxel_m=0.03, every=2)
    result = build_map(options)
    assert result.report["trajectory"]["from"] == str(tum)
    assert result.report["against_truth"]["trajectory"]["rmse_m"] < 1e-6
    assert result.report["walk"]["views"] == (result.report["walk"]["pairs"] + 1) // 2
    # the same pairs as a folder of images, with the same trajectory: the same model
    rec = Recording(walk)
    folder = write_folder(tmp_path / "folder", rec.calibration, rec.pairs())
    again = build_map(replace(options, source=f"folder:{folder}", out=tmp_path / "f"))
    assert "against_truth" not in again.report  # a folder carries no truth
    np.testing.assert_array_equal(again.model.vertices, result.model.vertices)
    np.testing.assert_array_equal(again.model.temp_c, result.model.temp_c)


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["--voxel-m", "0.5"], "--voxel-m: 0.5: give 0.002 .. 0.2 m"),
        (["--method", "best"], "--method: 'best': choose median, trimmed, mean, plain"),
        (["--trajectory", "nowhere.tum"], "--trajectory: nowhere.tum: no such file"),
        (["--every", "0"], "--every: must be >= 1"),
        (["sim"], "source: the simulated rig stands still and never ends"),
    ],
)
def test_bad_options_are_one_line(walk: Path, tmp_path: Path, args: list[str], line: str) -> None:
    source = [] if args == ["sim"] else [str(walk)]
    result = runner.invoke(app, ["map", *source, "-o", str(tmp_path / "m"), *args])
    assert result.exit_code != 0
    assert line in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_a_model_is_never_written_over(walk: Path, tmp_path: Path) -> None:
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "mesh.ply").write_text("mine")
    result = runner.invoke(app, ["map", str(walk), "-o", str(tmp_path / "m")])
    assert result.exit_code != 0 and "exists and is not an empty folder" in result.output
    assert (tmp_path / "m" / "mesh.ply").read_text() == "mine"


def test_a_bad_trajectory_file_is_one_line_naming_its_line(walk: Path, tmp_path: Path) -> None:
    tum = tmp_path / "bad.tum"
    tum.write_text("# t x y z qx qy qz qw\n1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 1\n")
    result = runner.invoke(
        app, ["map", str(walk), "-o", str(tmp_path / "m"), "--trajectory", str(tum)]
    )
    assert result.exit_code != 0
    assert f"{tum}:3: 7 fields; a TUM pose has 8" in result.output


def test_a_trajectory_on_another_clock_is_one_line(walk: Path, tmp_path: Path) -> None:
    truth = read_walk_truth(walk)
    assert truth is not None
    shifted = Trajectory(
        truth.trajectory.times_s + 1000.0,
        truth.trajectory.rotations,
        truth.trajectory.translations_m,
    )
    tum = shifted.save_tum(tmp_path / "late.tum")
    result = runner.invoke(
        app, ["map", str(walk), "-o", str(tmp_path / "m"), "--trajectory", str(tum)]
    )
    assert result.exit_code != 0
    assert "give the poses on the frames' clock" in result.output
    assert len(result.output.strip().splitlines()) == 1
