"""``--source folder:PATH``: images from any rig, with rig.yaml and frames.csv."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from thermodepth.app.run import RunOptions, run
from thermodepth.errors import InputError
from thermodepth.frames import thermal_output
from thermodepth.io.folder import write_folder
from thermodepth.radiometry import ThermalOutput
from thermodepth.sim import Rig, camera_pose, plate_scene
from thermodepth.sources import open_source

SETTINGS = "hotspots: {threshold_c: 45}\nrois: [{name: plate, rect: [300, 150, 550, 330]}]\n"


def sim_folder(tmp_path: Path, thermal: str = "p2pro", depth: str = "848x480", n: int = 6) -> Path:
    """A folder written from a simulator run (after the power-on shutter)."""
    rig = Rig.of_cameras(plate_scene(chip_temp_c=70.0), camera_pose(1.0), thermal, depth)
    rig.start_s = 1.0
    return write_folder(tmp_path / "rig", rig.calibration, rig.frames(n))


def measurements(out: Path) -> list[str]:
    return (out / "measurements.jsonl").read_text().splitlines()


@pytest.mark.parametrize(("thermal", "depth"), [("p2pro", "848x480"), ("lepton3", "1280x720")])
def test_a_folder_of_a_simulator_run_measures_as_the_run(
    tmp_path: Path, thermal: str, depth: str
) -> None:
    settings = tmp_path / "s.yaml"
    settings.write_text(SETTINGS)
    sim = run(
        RunOptions(
            f"sim:thermal={thermal},depth={depth}",
            settings,
            14,
            tmp_path / "sim",
            record=tmp_path / "sim.zarr",
        )
    )
    replay = open_source(f"recording:{tmp_path / 'sim.zarr'}")
    folder = write_folder(tmp_path / "rig", replay.calibration, replay)  # type: ignore[arg-type]
    rig = yaml.safe_load((folder / "rig.yaml").read_text())
    if thermal == "p2pro":  # its frames say 1/64 K: the folder's rig.yaml says it too
        assert rig["thermal"]["output"] == {"kind": "kelvin", "scale_k": 0.015625, "offset_k": 0.0}
    got = run(RunOptions(f"folder:{folder}", settings, out_dir=tmp_path / "folder"))
    assert got.frames == sim.frames == 14
    assert measurements(tmp_path / "folder") == measurements(tmp_path / "sim")
    assert "plate" in measurements(tmp_path / "sim")[-1]  # after the power-on shutter


def test_frames_csv_read_by_name_is_the_pairs_written(tmp_path: Path) -> None:
    """Each column of frames.csv, read by its header name, holds that field of its pair."""
    rig = Rig.of_cameras(plate_scene(chip_temp_c=70.0), camera_pose(1.0), "lepton3", "848x480")
    pairs = list(rig.frames(4))
    folder = write_folder(tmp_path / "rig", rig.calibration, pairs)
    with (folder / "frames.csv").open(newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(pairs) == 4
    assert any(p.telemetry.in_ffc for p in pairs) and not all(p.telemetry.in_ffc for p in pairs)
    for row, pair in zip(rows, pairs, strict=True):
        assert row["depth"] == f"depth/{pair.index:06d}.png"
        assert row["thermal"] == f"thermal/{pair.index:06d}.png"
        assert float(row["depth_time_s"]) == pair.depth_time_s
        assert float(row["thermal_time_s"]) == pair.thermal_time_s
        assert pair.depth_time_s != pair.thermal_time_s  # a swap of the two would show
        assert float(row["fpa_temp_c"]) == pair.telemetry.fpa_temp_c
        assert int(row["in_ffc"]) == pair.telemetry.in_ffc
        assert row["ir"] == ("" if pair.ir is None else f"ir/{pair.index:06d}.png")


def test_rows_that_cannot_be_read_are_one_line_each(tmp_path: Path) -> None:
    folder = sim_folder(tmp_path)
    rows = list(csv.DictReader((folder / "frames.csv").open()))
    rows[1]["thermal"] = "thermal/missing.png"
    rows[2]["depth_time_s"] = "soon"
    (folder / "junk.png").write_text("not a png")
    rows[3]["depth"] = "junk.png"
    with (folder / "frames.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    told: list[str] = []
    src = open_source(f"folder:{folder}", warn=told.append)
    pairs = list(src)
    assert len(pairs) == 3 and src.counters() == {"folder_bad_rows": 3}
    assert told == [
        f"{folder}/frames.csv: line 3: {folder}/thermal/missing.png: no such file; the row is "
        "skipped",
        f"{folder}/frames.csv: line 4: depth_time_s is not a number; the row is skipped",
        f"{folder}/frames.csv: line 5: {folder}/junk.png: not an image OpenCV can read; the "
        "row is skipped",
    ]


def test_an_image_of_another_size_stops_with_one_line(tmp_path: Path) -> None:
    folder = sim_folder(tmp_path, n=2)
    cv2.imwrite(str(folder / "thermal" / "000001.png"), np.zeros((120, 160), np.uint16))
    src = open_source(f"folder:{folder}")
    with pytest.raises(InputError) as info:
        list(src)
    assert str(info.value) == (
        f"{folder}/thermal/000001.png: the thermal image is 160x120 but rig.yaml's thermal "
        "camera is 256x192"
    )


def test_float_kelvin_rows_by_row_and_in_time(tmp_path: Path) -> None:
    folder = sim_folder(tmp_path, "lepton3.5", n=4)
    rows = list(csv.DictReader((folder / "frames.csv").open()))
    for row in rows:  # the thermal images as float kelvin .npy, as other tools save them
        values = cv2.imread(str(folder / row["thermal"]), cv2.IMREAD_UNCHANGED)
        npy = folder / row["thermal"].replace(".png", ".npy")
        np.save(npy, (values * 0.01).astype(np.float32))
        row["thermal"] = str(npy.relative_to(folder))
    for timed in (True, False):
        with (folder / "frames.csv").open("w", newline="") as fh:
            keep = list(rows[0]) if timed else ["depth", "thermal", "fpa_temp_c", "in_ffc"]
            w = csv.DictWriter(fh, keep, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)
        src = open_source(f"folder:{folder}")
        pairs = list(src)
        assert len(pairs) == 4
        out = thermal_output(pairs[0].telemetry, ThermalOutput())
        assert out == ThermalOutput.kelvin_per(1 / 64)  # float kelvin held at 1/64 K
        kelvin = pairs[0].thermal[60, 80] / 64
        assert 290 < kelvin < 320
        if timed:  # paired in time: the same rule (and statistics) as live cameras
            assert src.pairing is not None and src.pairing.pairs == 4
        else:
            assert src.paired_by == "the rows of frames.csv"
            assert [p.thermal_time_s for p in pairs] == [0.0, 1.0, 2.0, 3.0]


def test_a_folder_without_its_files(tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match=r"empty/rig.yaml: cannot read"):
        open_source(f"folder:{tmp_path / 'empty'}")
    folder = sim_folder(tmp_path, n=1)
    (folder / "frames.csv").write_text("depth,image\nd.png,t.png\n")
    with pytest.raises(InputError, match=r"frames.csv: missing column thermal"):
        open_source(f"folder:{folder}")


def test_a_folder_works_wherever_a_source_does(tmp_path: Path) -> None:
    # capture-board finds the board in the folder's infrared images; view and snapshots draw
    # a P2 Pro's 256x192 on a D435's 848x480
    from thermodepth.app.capture import CaptureOptions, capture_board
    from thermodepth.board import BoardSpec
    from thermodepth.sim.protocols import simulate_board_session

    board = BoardSpec.parse("checkerboard:9x6", 0.03)
    session = simulate_board_session(
        tmp_path / "board.zarr", board, 3, seed=2, camera="p2pro", depth="848x480"
    )
    replay = open_source(f"recording:{session}")
    folder = write_folder(tmp_path / "boards", replay.calibration, replay)  # type: ignore[arg-type]
    assert (folder / "ir").is_dir()
    result = capture_board(CaptureOptions(f"folder:{folder}", tmp_path / "pairs", 0.03))
    assert len(result.kept) >= 2
    pytest.importorskip("rerun", reason="the viewer needs the viewer extra (rerun-sdk)")
    settings = tmp_path / "s.yaml"
    settings.write_text("viewer: {temp_range_c: [20, 80]}\n")
    rig = sim_folder(tmp_path, n=14)
    out = tmp_path / "out"
    got = run(
        RunOptions(
            f"folder:{rig}", settings, out_dir=out, snapshots=10, viewer_save=tmp_path / "v.rrd"
        )
    )
    assert got.frames == 14 and (tmp_path / "v.rrd").stat().st_size > 0
    png = out / "snapshots" / "frame_000010.png"
    assert png.exists() and png.with_suffix(".ply").exists()
