"""One camera's intrinsics from single views, false-colour captures, and guided capture of
board pairs from a recording of a board shown to the simulated rig."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

import thermodepth.sources
from thermodepth.app.capture import CaptureOptions, capture_board
from thermodepth.board import BoardSpec
from thermodepth.calibrate import load_image, run_calibration
from thermodepth.calibrate.capture import BoardCapture
from thermodepth.calibration import Calibration
from thermodepth.cli import app
from thermodepth.errors import InputError
from thermodepth.evaluation import registration_difference_px
from thermodepth.palettes import apply_palette
from thermodepth.sim.protocols import simulate_board_session, simulate_targets
from thermodepth.sim.rig import default_calibration

runner = CliRunner()
BOARD = BoardSpec.parse("checkerboard:9x6", 0.03)
POSES, SEED = 8, 1  # simulate_targets and the board session place the same poses
VIEWS = 20  # single views of the board for calibrate-camera


def registration_error(cal: Calibration) -> np.ndarray:
    """Thermal px between where ``cal`` and the truth put depth pixels at 0.5-3 m."""
    return registration_difference_px(
        default_calibration(), cal, np.linspace(0.5, 3.0, 6), step_px=16
    )


@pytest.fixture(scope="module")
def targets(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("targets")
    simulate_targets(out, BOARD, POSES, seed=SEED)
    return out


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The same poses shown to the rig: held 0.7 s, moved for 0.35 s, FFC every 5 s."""
    out = tmp_path_factory.mktemp("session") / "board.zarr"
    return simulate_board_session(out, BOARD, POSES, seed=SEED, ffc_interval_s=5.0)


@pytest.fixture(scope="module")
def captured(session: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, object]:
    out = tmp_path_factory.mktemp("pairs")
    result = capture_board(CaptureOptions(f"recording:{session}", out, 0.03))
    return out, result


# -- capture-board ------------------------------------------------------------------------------


def test_captured_pairs_calibrate_as_well_as_simulated_captures(
    captured: tuple[Path, object], targets: Path
) -> None:
    out, result = captured
    assert result.stopped == "end"  # type: ignore[attr-defined]
    kept = result.kept  # type: ignore[attr-defined]
    assert len(kept) >= POSES - 1  # one pose per hold, at most one missed (measured: 7 of 8)
    for stem in kept:  # every pair whole, in the names calibrate pairs
        assert Path(f"{stem}_ir.png").is_file() and Path(f"{stem}_thermal.npy").is_file()
    assert np.load(f"{kept[0]}_thermal.npy").dtype == np.uint16  # raw counts
    verdicts = result.verdicts  # type: ignore[attr-defined]
    # the session has moving pairs, FFC frames and holds longer than one pair
    assert verdicts["moving"] >= POSES - 1 and verdicts["shutter closed"] >= 2
    assert verdicts["adds nothing new"] > 0
    mine = run_calibration(out, BOARD)
    ref = run_calibration(targets, BOARD)
    err_mine, err_ref = registration_error(mine.calibration), registration_error(ref.calibration)
    # measured: RMS 0.029 against 0.029 px, max 0.18 against 0.13 px (10 poses, seed 1)
    assert np.sqrt(np.mean(err_mine**2)) < 1.5 * np.sqrt(np.mean(err_ref**2)) + 0.01
    assert err_mine.max() < 0.3


def test_a_frame_with_the_shutter_closed_is_never_kept(tmp_path: Path, targets: Path) -> None:
    ir = cv2.imread(str(targets / "pose00_ir.png"), cv2.IMREAD_UNCHANGED)
    counts = cv2.imread(str(targets / "pose00_thermal.png"), cv2.IMREAD_UNCHANGED)
    capture = BoardCapture(BOARD, tmp_path)
    assert capture.offer(ir, counts, in_ffc=False).reason == "moving"  # nothing to compare with
    assert capture.offer(ir, counts, in_ffc=True).reason == "shutter closed"
    assert capture.offer(ir, counts, in_ffc=False).reason == "moving"  # the FFC broke the run
    assert capture.offer(ir, counts, in_ffc=False).kept
    assert capture.offer(ir, counts, in_ffc=False).reason == "adds nothing new"
    assert len(capture.kept) == 1


def test_numbering_continues_after_pairs_already_there(
    captured: tuple[Path, object], tmp_path: Path, session: Path
) -> None:
    out, result = captured
    again = tmp_path / "pairs"
    shutil.copytree(out, again)
    second = capture_board(CaptureOptions(f"recording:{session}", again, 0.03, count=2))
    assert second.stopped == "count" and len(second.kept) == 2
    n = len(result.kept)  # type: ignore[attr-defined]
    assert [p.name for p in second.kept] == [f"capture{n:03d}", f"capture{n + 1:03d}"]


def test_ctrl_c_keeps_every_pair(
    session: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    real = thermodepth.sources.open_source

    def interrupted(spec: str, *args: object, **kw: object) -> object:
        src = real(spec, *args, **kw)  # type: ignore[arg-type]
        events = src.events

        def until_interrupted():  # type: ignore[no-untyped-def]
            for i, e in enumerate(events()):
                if i == 60:  # a few pairs in: three holds
                    raise KeyboardInterrupt
                yield e

        src.events = until_interrupted  # type: ignore[method-assign]
        return src

    monkeypatch.setattr(thermodepth.sources, "open_source", interrupted)
    result = capture_board(CaptureOptions(f"recording:{session}", tmp_path / "p", 0.03))
    assert result.stopped == "interrupted" and len(result.kept) >= 2
    files = sorted(p.name for p in (tmp_path / "p").iterdir())
    assert len(files) == 2 * len(result.kept)  # whole pairs, no temporary file left


def test_capture_bad_input_is_one_line(tmp_path: Path, session: Path) -> None:
    from thermodepth.io.recording import Recording, RecordingWriter

    no_ir = tmp_path / "no_ir.zarr"
    rec = Recording(session)
    with RecordingWriter(no_ir, rec.calibration) as w:
        for m in list(rec.matches())[:2]:
            w.add_pair(m.pair.__class__(m.pair.depth, m.pair.thermal, 0.0, 0.0, m.pair.telemetry))
    res = runner.invoke(
        app,
        ["capture-board", "--source", f"recording:{no_ir}", "--square-m", "0.03", "-o",
         str(tmp_path / "p")],
    )  # fmt: skip
    assert res.exit_code == 2
    assert res.output.strip().splitlines() == [
        f"error: recording:{no_ir}: no infrared image with the depth frames (live: the IR stream "
        "is asked for; a recording needs record --ir)"
    ]
    (tmp_path / "file").write_text("x")
    res = runner.invoke(
        app,
        ["capture-board", "--source", f"recording:{session}", "--square-m", "0.03", "-o",
         str(tmp_path / "file")],
    )  # fmt: skip
    assert res.exit_code == 2 and "not a folder (pairs go into a folder)" in res.output


def test_capture_board_command(session: Path, tmp_path: Path) -> None:
    res = runner.invoke(
        app,
        ["capture-board", "--source", f"recording:{session}", "--square-m", "0.03", "-o",
         str(tmp_path / "p"), "--count", "2"],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    assert f"kept 2 pairs in {tmp_path / 'p'}" in text and "stopped: count" in text
    # the wrong board: nothing kept, and the line says what to check (on the first holds)
    short = first_pairs(session, 8, tmp_path / "short.zarr")
    res = runner.invoke(
        app,
        ["capture-board", "--source", f"recording:{short}", "--square-m", "0.03", "-o",
         str(tmp_path / "q"), "--board", "checkerboard:7x5"],
    )  # fmt: skip
    assert res.exit_code == 0
    assert "warning: no pair kept: the board was never seen whole and still" in " ".join(
        res.output.split()
    )


def first_pairs(recording: Path, n: int, out: Path) -> Path:
    """A recording of the first ``n`` pairs of another."""
    from thermodepth.io.recording import Recording, RecordingWriter

    rec = Recording(recording)
    with RecordingWriter(out, rec.calibration) as w:
        for i, m in enumerate(rec.matches()):
            if i == n:
                break
            w.add_match(m)
    return out


# -- calibrate-camera ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def views(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """VIEWS simulated views of the board (the thermal images are the single views)."""
    out = tmp_path_factory.mktemp("views")
    simulate_targets(out, BOARD, VIEWS, seed=4)
    return out


def test_calibrate_camera_writes_intrinsics_and_report(views: Path, tmp_path: Path) -> None:
    out = tmp_path / "thermal.yaml"
    (views / "notes.txt").write_text("not an image")
    res = runner.invoke(app, ["calibrate-camera", str(views), "--square-m", "0.03", "-o", str(out)])
    assert res.exit_code == 0, res.output
    report = json.loads((tmp_path / "calib_report.json").read_text())
    assert report["camera"] == "thermal" and report["images_found"] == VIEWS
    assert report["images_used"] >= VIEWS - 2 and report["rms_px"] < 0.1
    assert {s["reason"] for s in report["skipped"]} <= {"no checkerboard:9x6 found"}
    assert (tmp_path / "calib_report.png").is_file()
    truth = default_calibration().thermal
    import yaml

    got = yaml.safe_load(out.read_text())
    assert set(got) == {"width", "height", "fx", "fy", "cx", "cy", "distortion"}
    for key in ("fx", "fy", "cx", "cy"):  # measured within 0.3 % (seed 4)
        assert got[key] == pytest.approx(getattr(truth, key), rel=0.005)


def test_thermal_intrinsics_held_fixed_in_the_stereo_step(
    views: Path, targets: Path, tmp_path: Path
) -> None:
    intrinsics = tmp_path / "thermal.yaml"
    runner.invoke(
        app, ["calibrate-camera", str(views), "--square-m", "0.03", "-o", str(intrinsics)]
    )
    res = runner.invoke(
        app,
        ["calibrate", str(targets), "--square-m", "0.03", "-o", str(tmp_path / "c.yaml"),
         "--thermal-intrinsics", str(intrinsics)],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    cal = Calibration.load(tmp_path / "c.yaml")
    import yaml

    held = yaml.safe_load(intrinsics.read_text())
    assert cal.thermal.fx == held["fx"] and list(cal.thermal.distortion) == held["distortion"]
    report = json.loads((tmp_path / "calib_report.json").read_text())
    assert report["thermal_camera"]["model"] == "fixed"
    err = registration_error(cal)
    assert err.max() < 0.3  # VIEWS views for the intrinsics, 8 pairs for the transform


def test_calibrate_camera_bad_input_is_one_line(tmp_path: Path, views: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "a.txt").write_text("x")
    res = runner.invoke(app, ["calibrate-camera", str(empty), "--square-m", "0.03"])
    assert res.exit_code == 2 and res.output.strip().startswith(f"error: {empty}: no images")
    # no board in any image: what and which files, nothing written
    blank = tmp_path / "blank"
    blank.mkdir()
    for i in range(6):
        cv2.imwrite(str(blank / f"v{i}.png"), np.full((120, 160), 8000 + i, np.uint16))
    out = tmp_path / "t.yaml"
    res = runner.invoke(app, ["calibrate-camera", str(blank), "--square-m", "0.03", "-o", str(out)])
    assert res.exit_code == 2 and len(res.output.strip().splitlines()) == 1
    assert "only 0 usable thermal views of 6" in res.output and "v0.png: no checkerboard" in (
        res.output
    )
    assert not out.exists()
    # images of different sizes: the files that differ
    mixed = tmp_path / "mixed"
    shutil.copytree(views, mixed)
    cv2.imwrite(str(mixed / "pose00_thermal.png"), np.zeros((60, 80), np.uint16))
    res = runner.invoke(app, ["calibrate-camera", str(mixed), "--square-m", "0.03"])
    assert res.exit_code == 2
    differ = f"pose00_thermal.png is 80x60, but {VIEWS - 1} are 160x120"
    assert f"thermal image sizes differ: {differ}" in res.output
    res = runner.invoke(
        app, ["calibrate-camera", str(views), "--square-m", "0.03", "--camera", "x"]
    )
    assert res.exit_code == 2 and "--camera: unknown 'x'; choose thermal or depth" in res.output


# -- false colour -------------------------------------------------------------------------------


def test_false_colour_captures_calibrate_as_the_counts_do(views: Path, tmp_path: Path) -> None:
    # the same captures saved as a viewer saves them: 8-bit ironbow of a stretched frame
    ironbow = tmp_path / "ironbow"
    ironbow.mkdir()
    for f in views.glob("*_ir.png"):
        shutil.copy(f, ironbow / f.name)
    for f in views.glob("*_thermal.png"):
        counts = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(ironbow / f.name), apply_palette(counts, "ironbow")[..., ::-1])
    rgb = run_calibration(ironbow, BOARD)
    raw = run_calibration(views, BOARD)
    assert len(rgb.used) == len(raw.used) == VIEWS
    # measured: thermal RMS 0.050 / 0.051 px, registration RMS 0.080 / 0.081 px (max 0.267 both)
    assert rgb.thermal_fit.rms_px == pytest.approx(raw.thermal_fit.rms_px, rel=0.1)
    err_rgb, err_raw = registration_error(rgb.calibration), registration_error(raw.calibration)
    assert np.sqrt(np.mean(err_rgb**2)) < np.sqrt(np.mean(err_raw**2)) + 0.01
    assert err_rgb.max() < 0.3


def test_a_colour_image_that_is_no_thermal_palette_is_refused(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    photo = tmp_path / "photo.png"
    cv2.imwrite(str(photo), rng.integers(0, 256, (120, 160, 3)).astype(np.uint8))
    with pytest.raises(InputError) as info:
        load_image(photo, thermal=True)
    assert str(info.value).startswith(f"{photo}: not a thermal image: its colours are not")
    assert load_image(photo).ndim == 2  # as a depth camera's colour image: grey
