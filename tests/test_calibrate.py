"""Target-based calibration: OpenCV's real stereo samples, simulated heated-board captures
with a known truth, every kind of bad input, the naming rules, image formats and the CLI."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from conftest import CliProcess
from thermodepth.board import BoardSpec
from thermodepth.calibrate import (
    CalibrationResult,
    canonical_order,
    coverage_grid,
    detect_board,
    discover_pairs,
    flag_outliers,
    grid_continues,
    load_image,
    load_intrinsics,
    match_order,
    plot_report,
    run_calibration,
    stretch_to_unit,
    upscale_factor,
    write_report_json,
)
from thermodepth.calibration import Calibration
from thermodepth.camera import RigidTransform
from thermodepth.cli import app
from thermodepth.errors import InputError
from thermodepth.evaluation import registration_difference_px
from thermodepth.sim.protocols import simulate_targets

SHARED_DATA = Path(
    os.environ.get("THERMODEPTH_SHARED_DATA", Path(__file__).resolve().parents[2] / "shared/data")
)
REAL = SHARED_DATA / "opencv-stereo-chessboard"
needs_real = pytest.mark.skipif(
    not REAL.is_dir(),
    reason=f"{REAL} is absent: OpenCV's stereo chessboard samples live in ../shared/data "
    "next to the clone (or set THERMODEPTH_SHARED_DATA)",
)
BOARD_REAL = BoardSpec.parse("checkerboard:9x6", 1.0)  # square size unknown: results in squares
BOARD_SIM = BoardSpec.parse("checkerboard:9x6", 0.03)
runner = CliRunner()


def copy_real(dest: Path, keys: list[str]) -> Path:
    """A folder with the real pairs left<key>.jpg / right<key>.jpg."""
    dest.mkdir(parents=True, exist_ok=True)
    for k in keys:
        for side in ("left", "right"):
            shutil.copy(REAL / f"{side}{k}.jpg", dest / f"{side}{k}.jpg")
    return dest


REAL_KEYS = ["01", "02", "03", "04", "05", "06", "07", "08", "09", "11", "12", "13", "14"]


# -- real images: OpenCV's own stereo samples ----------------------------------------------


@needs_real
def test_real_pairs_reproduce_opencvs_reference_figures() -> None:
    # The reference procedure of the data's README: cornerSubPix (11x11 window) refinement,
    # calibrateCamera with default flags (all five distortion terms), stereoCalibrate with
    # fixed intrinsics. The README gives 3 decimals from OpenCV 5.0.0 and 4.12 (which agree):
    # 0.01 px covers that rounding and small numeric differences between builds.
    result = run_calibration(
        REAL,
        BOARD_REAL,
        thermal_model="full",
        depth_model="full",
        thermal_refine="cornersubpix",
    )
    assert [p.name for p in result.used] == REAL_KEYS
    assert result.skipped == () and result.unmatched == ()
    assert result.depth_fit.rms_px == pytest.approx(0.408, abs=0.01)
    assert result.thermal_fit.rms_px == pytest.approx(0.458, abs=0.01)
    assert result.stereo.rms_px == pytest.approx(0.447, abs=0.01)
    # T = (-3.344, 0.042, 0.053) squares (README, 3 decimals): 0.01 squares
    t = result.calibration.thermal_from_depth.translation_m
    np.testing.assert_allclose(t, [-3.344, 0.042, 0.053], atol=0.01)
    assert result.stereo.baseline_m == pytest.approx(3.3446, abs=0.01)


@needs_real
def test_real_pairs_with_default_refinement_fit_better() -> None:
    # The fronto-parallel refinement (default for the thermal camera) on the same images:
    # the right camera's RMS falls from 0.458 to about 0.27 px (measured 0.271); the baseline
    # moves by less than 1 % of its length (measured 3.326 squares vs 3.344).
    result = run_calibration(REAL, BOARD_REAL, thermal_model="full", depth_model="full")
    assert result.thermal_fit.rms_px < 0.30
    assert result.stereo.rms_px < 0.40
    assert result.stereo.baseline_m == pytest.approx(3.344, rel=0.01)


@needs_real
def test_real_outliers_are_flagged_and_can_be_dropped() -> None:
    result = run_calibration(
        REAL, BOARD_REAL, thermal_model="full", depth_model="full", thermal_refine="cornersubpix"
    )
    flagged = {p.name for p, f in zip(result.used, result.outliers, strict=True) if f}
    # pair 02 is the known bad one of OpenCV's samples: 1.2 px in both cameras, 6x the median
    assert "02" in flagged
    assert any("outlier images" in w for w in result.warnings)
    again = run_calibration(
        REAL,
        BOARD_REAL,
        thermal_model="full",
        depth_model="full",
        thermal_refine="cornersubpix",
        drop_outliers=True,
    )
    assert {p.name for p in again.dropped} == flagged
    assert not {p.name for p in again.used} & flagged
    assert again.stereo.rms_px < result.stereo.rms_px - 0.1  # measured 0.447 -> 0.242


@needs_real
def test_corner_order_agrees_between_the_two_cameras_of_real_pairs() -> None:
    # stereoCalibrate needs corner k to be the same physical corner in both images: with a
    # mismatched order one pair's stereo error would be tens of pixels, not < 1.3 px.
    result = run_calibration(REAL, BOARD_REAL, thermal_refine="cornersubpix")
    assert float(np.max(result.stereo.per_view_rms_px)) < 1.3


# -- simulated heated-board captures with a known truth ------------------------------------


@pytest.fixture(scope="module")
def sim_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """25 poses of a heated 9x6 checkerboard (3 cm squares), the simulator's default seed."""
    out = tmp_path_factory.mktemp("targets")
    simulate_targets(out, BOARD_SIM, n_poses=25, seed=0)
    return out


@pytest.fixture(scope="module")
def sim_result(sim_dir: Path) -> CalibrationResult:
    return run_calibration(sim_dir, BOARD_SIM)


def test_simulated_captures_recover_the_true_calibration(
    sim_dir: Path, sim_result: CalibrationResult
) -> None:
    truth = Calibration.load(sim_dir / "truth_calibration.yaml")
    cal = sim_result.calibration
    assert len(sim_result.used) >= 24  # measured: 24 of 25 (one pose's thermal view is not found)
    # The targets, on the simulator's default seed. They are near what 25 views of a
    # 160x120 camera can give: corners are good to ~0.05 px, so the thermal focal length and
    # principal point are known to ~0.1-0.15 % (1 sigma), and their errors carry into the
    # translation (fx) and the rotation (cx, cy). Over seeds 0-9 (docs/calibration.md) the
    # translation is within 1 mm in 8 runs (worst 1.33 mm), the rotation within 0.1 deg in 9
    # (worst 0.18), fx, fy, cx, cy within 0.5 % in 9 (worst 0.56 %), registration in all 10.
    t, tt = cal.thermal_from_depth, truth.thermal_from_depth
    assert np.linalg.norm(t.translation_m - tt.translation_m) < 0.001  # measured 0.09 mm
    assert (t @ tt.inverse()).angle_deg < 0.1  # measured 0.087 deg
    for key in ("fx", "fy", "cx", "cy"):  # measured -0.07, -0.07, 0.14, 0.35 %
        assert getattr(cal.thermal, key) == pytest.approx(getattr(truth.thermal, key), rel=0.005)
    # distortion close to the truth [-0.08, 0.02, 0.0004, -0.0003, 0]: k1 within 0.01 and k2
    # within 0.03 (they trade off against each other; measured -0.078, 0.014), p1, p2 within
    # 0.001 (measured 0.0006, -0.0000), k3 held at 0 (the thermal default, "no-k3")
    d, dt = cal.thermal.distortion, truth.thermal.distortion
    assert abs(d[0] - dt[0]) < 0.01 and abs(d[1] - dt[1]) < 0.03
    assert np.all(np.abs(d[2:4] - dt[2:4]) < 0.001) and d[4] == 0.0
    # the depth camera from its IR images (truth: fx 645, centre (639.5, 359.5), no
    # distortion): fx within 0.1 %, principal point within 1 px
    assert cal.depth.fx == pytest.approx(645.0, rel=0.001)
    assert abs(cal.depth.cx - 639.5) < 1.0 and abs(cal.depth.cy - 359.5) < 1.0


def test_registration_with_recovered_calibration_matches_the_truth(
    sim_dir: Path, sim_result: CalibrationResult
) -> None:
    # depth pixel -> 3D (depth intrinsics) -> thermal frame -> thermal pixel, under both
    # calibrations, for depths 0.5..3 m, over the pixels that land inside the thermal image
    truth = Calibration.load(sim_dir / "truth_calibration.yaml")
    err = registration_difference_px(
        truth, sim_result.calibration, np.linspace(0.5, 3.0, 6), step_px=16
    )
    assert err.size > 5000
    assert np.all(np.isfinite(err))
    assert float(np.max(err)) < 0.3  # the bound; measured 0.052 px (worst of 10: 0.29)
    assert float(np.sqrt(np.mean(err**2))) < 0.1  # measured 0.015 px (worst of 10: 0.084)


def test_heated_board_is_found_in_the_negative_of_the_thermal_image(
    sim_dir: Path, sim_result: CalibrationResult
) -> None:
    # paint glows, bare metal reflects the cooler room: the thermal image is the IR image's
    # negative, and OpenCV needs a light border around the squares
    assert all(sim_result.thermal_inverted)
    th = load_image(sim_dir / "pose01_thermal.png")
    assert th.dtype == np.uint16 and th.shape == (120, 160)
    det = detect_board(th, BOARD_SIM, stretch=True)
    assert det is not None and det.inverted and det.upscale == 4


def test_circle_grid_calibrates(tmp_path: Path) -> None:
    board = BoardSpec.parse("circles:4x11", 0.02)
    # 10 poses and 4x4 rays per thermal pixel to keep the test short (circles render slowly)
    simulate_targets(tmp_path, board, n_poses=10, seed=0, thermal_supersample=4)
    result = run_calibration(tmp_path, board)
    truth = Calibration.load(tmp_path / "truth_calibration.yaml")
    assert len(result.used) >= 6  # measured 9: one view's blobs are not all found
    # Loose bounds: the simulated grid's circles are as wide as the grid step, so after the
    # Lepton's blur neighbouring blobs nearly touch and some views' centres are biased by
    # ~0.1 px (docs/calibration.md); measured 0.047 px RMS, 0.72 mm, fx 0.05 %.
    assert result.thermal_fit.rms_px < 0.1
    dt = (
        result.calibration.thermal_from_depth.translation_m - truth.thermal_from_depth.translation_m
    )
    assert np.linalg.norm(dt) < 0.002
    assert result.calibration.thermal.fx == pytest.approx(truth.thermal.fx, rel=0.005)


def test_fixed_depth_intrinsics_are_held(sim_dir: Path, tmp_path: Path) -> None:
    truth_path = sim_dir / "truth_calibration.yaml"
    depth, scale = load_intrinsics(truth_path, "depth")  # a whole calibration file: its depth
    assert scale == 0.001 and depth == Calibration.load(truth_path).depth
    flat = tmp_path / "d435.json"
    flat.write_text(json.dumps(yaml.safe_load(truth_path.read_text())["depth"]))
    depth2, _ = load_intrinsics(flat, "depth")  # just the camera's fields
    assert depth2 == depth
    result = run_calibration(sim_dir, BOARD_SIM, depth_intrinsics=depth)
    assert result.calibration.depth == depth
    assert result.depth_fit.model == "fixed"
    assert result.depth_fit.rms_px < 0.15  # the true intrinsics fit the IR corners (0.08 px)


def test_bad_depth_intrinsics_files(tmp_path: Path) -> None:
    bad = tmp_path / "depth.yaml"
    bad.write_text(
        "depth: {width: 1280, height: 720, fx: -1, fy: 645, cx: 639.5, cy: 359.5, "
        "distortion: [0, 0, 0, 0, 0]}\n"
    )
    with pytest.raises(InputError, match=r"depth\.yaml: depth\.fx"):
        load_intrinsics(bad, "depth")
    bad.write_text("width: 1280\n")
    with pytest.raises(InputError, match=r"depth\.yaml: height: missing"):
        load_intrinsics(bad, "depth")
    camera = (
        "width: 1280, height: 720, fx: 645, fy: 645, cx: 639.5, cy: 359.5, "
        "distortion: [0, 0, 0, 0, 0]"
    )
    for scale, message in ((".inf", "finite number"), ("-1", "greater than 0")):
        bad.write_text(f"depth: {{{camera}, depth_scale_m: {scale}}}\n")
        with pytest.raises(InputError, match=rf"depth\.yaml: depth\.depth_scale_m: .*{message}"):
            load_intrinsics(bad, "depth")


@needs_real
def test_depth_intrinsics_of_another_size_are_refused(tmp_path: Path) -> None:
    from thermodepth.camera import Intrinsics

    other = Intrinsics(1280, 720, 645.0, 645.0, 639.5, 359.5)
    with pytest.raises(InputError, match=r"^depth_intrinsics: size 1280x720 .*640x480"):
        run_calibration(REAL, BOARD_REAL, depth_intrinsics=other)


# -- bad input -----------------------------------------------------------------------------


@needs_real
def test_unreadable_image_is_skipped_and_named(tmp_path: Path) -> None:
    d = copy_real(tmp_path / "pairs", REAL_KEYS[:8])
    (d / "right03.jpg").write_bytes(b"not a jpeg at all")
    result = run_calibration(d, BOARD_REAL)
    assert "03" not in [p.name for p in result.used] and len(result.used) == 7
    (skip,) = result.skipped
    assert skip.pair.name == "03" and skip.files == (d / "right03.jpg",)
    assert "right03.jpg: unreadable" in skip.reason


@needs_real
def test_pose_without_a_board_in_one_camera_is_skipped_and_listed(tmp_path: Path) -> None:
    d = copy_real(tmp_path / "pairs", REAL_KEYS[:8])
    blank = np.full((480, 640), 128, np.uint8)
    cv2.imwrite(str(d / "left05.jpg"), blank)
    result = run_calibration(d, BOARD_REAL)
    assert [s.pair.name for s in result.skipped] == ["05"]
    assert result.skipped[0].files == (d / "left05.jpg",)
    assert result.skipped[0].reason == "no checkerboard:9x6 found in left05.jpg"
    # ... and listed at the end of the report
    report = result.report_dict()
    assert report["skipped"] == [
        {
            "name": "05",
            "reason": "no checkerboard:9x6 found in left05.jpg",
            "files": [str(d / "left05.jpg")],
        }
    ]


@needs_real
def test_fewer_than_six_usable_pairs_stop_with_how_many_and_why(tmp_path: Path) -> None:
    d = copy_real(tmp_path / "pairs", REAL_KEYS[:7])
    blank = np.full((480, 640), 128, np.uint8)
    cv2.imwrite(str(d / "right04.jpg"), blank)
    (d / "left06.jpg").write_bytes(b"")
    with pytest.raises(InputError) as exc:
        run_calibration(d, BOARD_REAL)
    msg = str(exc.value)
    assert "only 5 usable pairs of 7 (need at least 6)" in msg
    assert "1 without a board in one or both images (04)" in msg
    assert "1 with an unreadable image (06)" in msg


@needs_real
def test_a_board_of_the_wrong_size_is_named_as_the_likely_cause(tmp_path: Path) -> None:
    # OpenCV finds an 8x6 sub-grid on most views of the 9x6 board, a different one in the
    # two cameras; those pairs are skipped, and the message points at --board
    d = copy_real(tmp_path / "pairs", REAL_KEYS[:6])
    with pytest.raises(InputError) as exc:
        run_calibration(d, BoardSpec.parse("checkerboard:8x6", 1.0))
    msg = str(exc.value)
    assert "usable pairs of 6 (need at least 6)" in msg and "\n" not in msg
    assert "where the board has more corners" in msg
    assert "check --board: checkerboard:8x6 counts inner corners, columns x rows" in msg


@needs_real
def test_grid_continues_past_sub_grids_only() -> None:
    # the right size: no edge on any of OpenCV's 26 views; one column or row too few: the
    # pattern goes on past an edge in most views where OpenCV finds the sub-grid (every other
    # view: a search for a board that is not there takes OpenCV 1.5 s a view)
    paths = sorted(REAL.glob("*.jpg"))
    assert len(paths) == 26
    flagged, seen = 0, 0
    for i, path in enumerate(paths):
        img = load_image(path)
        right = detect_board(img, BOARD_REAL)
        assert right is not None and grid_continues(img, right.points_px, BOARD_REAL) == ()
        if i % 2:
            continue
        for smaller in ("checkerboard:8x6", "checkerboard:9x5"):
            board = BoardSpec.parse(smaller, 1.0)
            det = detect_board(img, board)
            if det is not None:
                seen += 1
                flagged += bool(grid_continues(img, det.points_px, board))
    assert seen >= 10 and flagged / seen >= 0.8


def test_grid_continues_on_simulated_lepton_views(sim_dir: Path) -> None:
    n = 0
    for path in sorted(sim_dir.glob("*_thermal.png")):
        img = load_image(path)
        det = detect_board(img, BOARD_SIM)
        if det is not None:  # a few of the 25 poses are too oblique for the Lepton
            n += 1
            assert grid_continues(img, det.points_px, BOARD_SIM) == (), path.name
    assert n >= 20
    small = BoardSpec.parse("checkerboard:7x5", 0.03)
    views = [load_image(p) for p in sorted(sim_dir.glob("*_thermal.png"))[:8]]
    dets = [(img, detect_board(img, small)) for img in views]
    found = [(img, det) for img, det in dets if det is not None]
    assert len(found) >= 4
    assert all(len(grid_continues(img, det.points_px, small)) >= 2 for img, det in found)


@needs_real
def test_pairs_that_do_not_match_by_name_are_reported(tmp_path: Path) -> None:
    d = copy_real(tmp_path / "pairs", REAL_KEYS[:6])
    shutil.copy(REAL / "left07.jpg", d / "left07.jpg")  # no right07
    shutil.copy(REAL / "right08.jpg", d / "notes.jpg")  # fits no rule
    (d / "README.md").write_text("not an image: ignored")
    result = run_calibration(d, BOARD_REAL)
    assert len(result.used) == 6
    reasons = {p.name: r for p, r in result.unmatched}
    assert set(reasons) == {"left07.jpg", "notes.jpg"}
    assert "no thermal image to pair with (expected right07.*)" in reasons["left07.jpg"]
    assert "fits no rule" in reasons["notes.jpg"]


@needs_real
def test_image_sizes_that_change_between_files_stop_naming_them(tmp_path: Path) -> None:
    d = copy_real(tmp_path / "pairs", REAL_KEYS[:7])
    img = cv2.imread(str(REAL / "right03.jpg"))
    cv2.imwrite(str(d / "right03.jpg"), cv2.resize(img, (320, 240)))
    with pytest.raises(
        InputError,
        match=r"thermal image sizes differ: right03\.jpg is 320x240, "
        r"but 6 are 640x480",
    ):
        run_calibration(d, BOARD_REAL)


def test_missing_or_empty_folder(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not a folder of image pairs"):
        discover_pairs(tmp_path / "nope")
    (tmp_path / "x.png").write_bytes(b"")
    with pytest.raises(InputError, match=r"no image pairs found \(naming rules"):
        discover_pairs(tmp_path)


# -- naming rules and image formats ---------------------------------------------------------


def test_naming_rules(tmp_path: Path) -> None:
    names = [
        "a_ir.png",
        "a_thermal.png",  # <stem>_ir + <stem>_thermal
        "b_color.tif",
        "b_thermal.npy",  # colour camera, any extension
        "c_RGB.jpg",
        "c_Thermal.tiff",  # case does not matter
        "left1.png",
        "right1.png",  # OpenCV's stereo samples: left = depth camera
        "d_ir.png",  # no partner
        "a_ir.npy",  # a second IR image for stem a
        "e_thermal.png",  # no partner
        "right9.png",  # no partner
        "photo.png",  # no rule
        "notes.txt",  # not an image: ignored
    ]
    for n in names:
        (tmp_path / n).write_bytes(b"")
    listing = discover_pairs(tmp_path)
    pairs = {p.name: (p.depth_path.name, p.thermal_path.name) for p in listing.pairs}
    assert pairs == {
        "a": ("a_ir.npy", "a_thermal.png"),  # sorted: a_ir.npy comes before a_ir.png
        "b": ("b_color.tif", "b_thermal.npy"),
        "c": ("c_RGB.jpg", "c_Thermal.tiff"),
        "1": ("left1.png", "right1.png"),
    }
    unmatched = {p.name: r for p, r in listing.unmatched}
    assert set(unmatched) == {"a_ir.png", "d_ir.png", "e_thermal.png", "right9.png", "photo.png"}
    assert unmatched["a_ir.png"] == "a_ir.npy already is the depth image"
    assert "expected d_thermal.*" in unmatched["d_ir.png"]
    assert "expected e_ir.* (or _color, _rgb)" in unmatched["e_thermal.png"]
    assert "expected left9.*" in unmatched["right9.png"]


def test_image_formats_load_with_their_values(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    counts = rng.integers(7000, 9000, (120, 160)).astype(np.uint16)  # 14-bit counts
    cv2.imwrite(str(tmp_path / "c.png"), counts)
    cv2.imwrite(str(tmp_path / "c.tif"), counts)
    np.save(tmp_path / "c.npy", counts)
    np.save(tmp_path / "f.npy", counts.astype(np.float32))
    for name in ("c.png", "c.tif", "c.npy"):
        img = load_image(tmp_path / name)
        assert img.dtype == np.uint16
        np.testing.assert_array_equal(img, counts)
    np.testing.assert_array_equal(load_image(tmp_path / "f.npy"), counts.astype(np.float32))
    grey = (counts // 64).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "g.png"), grey)
    np.testing.assert_array_equal(load_image(tmp_path / "g.png"), grey)
    colour = np.dstack([grey, grey, grey])
    cv2.imwrite(str(tmp_path / "rgb.png"), colour)
    np.testing.assert_array_equal(load_image(tmp_path / "rgb.png"), grey)
    (tmp_path / "bad.png").write_bytes(b"\x89PNG garbage")
    with pytest.raises(InputError, match=r"bad\.png: unreadable"):
        load_image(tmp_path / "bad.png")
    np.save(tmp_path / "cube.npy", np.zeros((2, 3, 4, 5)))
    with pytest.raises(InputError, match=r"cube\.npy: expected a 2-D numeric image"):
        load_image(tmp_path / "cube.npy")
    with pytest.raises(InputError, match=r"gone\.png: unreadable"):
        load_image(tmp_path / "gone.png")


def test_a_truncated_image_is_our_one_line_without_opencvs_warning(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    cv2.imwrite(str(tmp_path / "whole.png"), np.arange(64 * 48, dtype=np.uint16).reshape(48, 64))
    data = (tmp_path / "whole.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(data[: len(data) // 2])
    capfd.readouterr()
    with pytest.raises(InputError, match=r"cut\.png: unreadable"):
        load_image(tmp_path / "cut.png")
    assert capfd.readouterr().err == ""  # OpenCV's "PNG input buffer is incomplete" is muted
    assert cv2.utils.logging.getLogLevel() != cv2.utils.logging.LOG_LEVEL_ERROR  # restored


@needs_real
def test_14_bit_inverted_board_gives_the_same_corners(tmp_path: Path) -> None:
    # an 8-bit photo made into a low-contrast, inverted 14-bit "thermal" image (510 counts of
    # range on an 8000 offset, plus hot and dead pixels): the percentile stretch and the
    # polarity search find the same corners (cornerSubPix is blind to an affine intensity map)
    img = load_image(REAL / "left01.jpg")
    counts = (8000 + 2 * (255 - img.astype(np.uint16))).astype(np.uint16)
    counts[10, 10], counts[20, 30] = 16383, 0
    ref = detect_board(img, BOARD_REAL)
    got = detect_board(counts, BOARD_REAL, stretch=True)
    assert ref is not None and got is not None
    np.testing.assert_allclose(got.points_px, ref.points_px, atol=0.01)
    unit = stretch_to_unit(counts)
    assert unit is not None and np.percentile(unit, 1) == pytest.approx(0.0, abs=1e-3)
    assert stretch_to_unit(np.full((4, 4), 8000, np.uint16)) is None  # flat: nothing to find


def test_upscale_factor() -> None:
    assert upscale_factor((120, 160)) == 4  # Lepton 3
    assert upscale_factor((60, 80)) == 8  # Lepton 2.5
    assert upscale_factor((480, 640)) == 1 and upscale_factor((720, 1280)) == 1


# -- corner order and outliers --------------------------------------------------------------


def grid_points(angle_deg: float, board: BoardSpec = BOARD_REAL) -> np.ndarray:
    """Corners (N, 2) of a board seen square-on, turned by angle_deg, in OpenCV's order."""
    obj = board.object_points_m()[:, :2] * 20.0
    a = np.radians(angle_deg)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    return obj @ rot.T + [320.0, 240.0]


def test_canonical_order_undoes_a_detector_starting_at_the_other_end() -> None:
    pts = grid_points(10.0)
    np.testing.assert_array_equal(canonical_order(pts[::-1].copy(), BOARD_REAL), pts)
    np.testing.assert_array_equal(canonical_order(pts, BOARD_REAL), pts)
    # a mirrored order (each row reversed) is made right-handed again
    mirrored = pts.reshape(6, 9, 2)[:, ::-1].reshape(-1, 2)
    np.testing.assert_array_equal(canonical_order(mirrored, BOARD_REAL), pts)
    # upside down (turned 180 deg): the first corner is the top-left one again
    flipped = canonical_order(grid_points(190.0), BOARD_REAL)
    assert flipped[0, 0] < flipped[-1, 0] and flipped[0, 1] < flipped[-1, 1]


def test_match_order_makes_a_pair_agree_near_ninety_degrees() -> None:
    # a board standing on its end, seen at 89 deg by one camera and 91 deg by the other:
    # each image alone would start at opposite ends; the pair must agree
    a = canonical_order(grid_points(89.0), BOARD_REAL)
    b = canonical_order(grid_points(91.0), BOARD_REAL)
    assert np.linalg.norm(a[0] - b[0]) > 100  # different physical corners on their own
    b = match_order(a, b, BOARD_REAL)
    assert np.linalg.norm(a[0] - b[0]) < 10


def test_outlier_rule() -> None:
    e = np.array([0.20, 0.22, 0.18, 0.21, 0.19, 0.25, 0.23, 0.20, 1.2])
    np.testing.assert_array_equal(flag_outliers(e), [False] * 8 + [True])
    # all alike: nothing is an outlier, however small the spread (the 2 x median floor)
    assert not flag_outliers(np.array([0.100, 0.101, 0.099, 0.102, 0.130])).any()
    # two columns (two cameras): a row is flagged when either is
    two = np.column_stack([e, e[::-1]])
    np.testing.assert_array_equal(np.flatnonzero(flag_outliers(two)), [0, 8])


def test_coverage_grid_counts_points_per_cell() -> None:
    pts = np.array([[0.0, 0.0], [159.0, 119.0], [159.4, 119.4], [80.0, 60.0]])
    grid = coverage_grid(pts, 160, 120)
    assert grid.shape == (6, 8)
    assert grid[0, 0] == 1 and grid[-1, -1] == 2 and grid[3, 4] == 1 and grid.sum() == 4


# -- report files and the command line -----------------------------------------------------


def test_report_files(sim_result: CalibrationResult, tmp_path: Path) -> None:
    write_report_json(sim_result, tmp_path / "calib_report.json")
    plot_report(sim_result, tmp_path / "calib_report.png")
    rep = json.loads((tmp_path / "calib_report.json").read_text())
    assert rep["pairs_used"] == len(sim_result.used) == len(rep["per_image"])
    assert rep["thermal_camera"]["size"] == [160, 120]
    # the principal point's offset from the image centre (79.5, 59.5), px
    off = rep["thermal_camera"]["principal_point_offset_px"]
    assert off == pytest.approx(
        [sim_result.calibration.thermal.cx - 79.5, sim_result.calibration.thermal.cy - 59.5]
    )
    assert rep["stereo"]["baseline_mm"] == pytest.approx(1000 * sim_result.calibration.baseline_m)
    assert 0.5 < rep["coverage"]["thermal_fraction"] <= 1.0  # measured 0.77
    assert np.array(rep["coverage"]["thermal_cells"]).sum() == 54 * len(sim_result.used)
    png = cv2.imread(str(tmp_path / "calib_report.png"))
    assert png is not None and png.shape[1] > 1000


@needs_real
def test_cli_writes_calibration_and_reports(tmp_path: Path) -> None:
    d = copy_real(tmp_path / "pairs", REAL_KEYS)
    out = tmp_path / "out" / "calib.yaml"
    result = runner.invoke(
        app,
        [
            "calibrate",
            str(d),
            "--board",
            "checkerboard:9x6",
            "--square-m",
            "0.025",
            "-o",
            str(out),
            "--thermal-model",
            "full",
            "--depth-model",
            "full",
            "--thermal-refine",
            "cornersubpix",
        ],
    )
    assert result.exit_code == 0, result.output
    cal = Calibration.load(out)
    # 3.344 squares of 25 mm = 83.6 mm
    assert cal.baseline_m == pytest.approx(3.344 * 0.025, abs=0.01 * 0.025)
    rep = json.loads((out.parent / "calib_report.json").read_text())
    assert rep["stereo"]["rms_px"] == pytest.approx(0.447, abs=0.01)
    assert (out.parent / "calib_report.png").stat().st_size > 10_000
    assert "baseline mm" in result.output and "83.6" in result.output
    assert "outlier" in result.output


@needs_real
def test_cli_drop_outliers_and_fixed_depth_intrinsics(tmp_path: Path) -> None:
    d = copy_real(tmp_path / "pairs", REAL_KEYS)
    first = tmp_path / "first.yaml"
    assert (
        runner.invoke(app, ["calibrate", str(d), "--square-m", "0.025", "-o", str(first)]).exit_code
        == 0
    )
    out = tmp_path / "fixed.json"
    result = runner.invoke(
        app,
        [
            "calibrate",
            str(d),
            "--square-m",
            "0.025",
            "-o",
            str(out),
            "--depth-intrinsics",
            str(first),
            "--drop-outliers",
        ],
    )
    assert result.exit_code == 0, result.output
    assert Calibration.load(out).depth == Calibration.load(first).depth
    assert "dropped: 02" in result.output


@needs_real
def test_cli_error_is_one_line_with_exit_code_2(tmp_path: Path, cli_process: CliProcess) -> None:
    d = copy_real(tmp_path / "pairs", REAL_KEYS[:4])
    proc = cli_process("calibrate", str(d), "--square-m", "0.025", "-o", str(tmp_path / "c.yaml"))
    assert proc.returncode == 2
    err = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert err == ["error: only 4 usable pairs of 4 (need at least 6): capture more poses"]
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "c.yaml").exists()


def test_cli_bad_board_is_one_line(tmp_path: Path) -> None:
    result = runner.invoke(
        app, ["calibrate", str(tmp_path), "--board", "chess:9x6", "--square-m", "0.025"]
    )
    assert result.exit_code == 2
    assert "--board: expected checkerboard:COLSxROWS" in result.output
    for size in ("inf", "nan", "0"):
        result = runner.invoke(app, ["calibrate", str(tmp_path), "--square-m", size])
        assert result.exit_code == 2, size
        assert result.output.strip() == (
            f"error: --square-m: must be a finite length > 0, got {float(size)}"
        )


def test_simulated_pose_generator_keeps_boards_in_both_views() -> None:
    from thermodepth.sim.protocols import random_board_poses
    from thermodepth.sim.rig import default_calibration

    cal = default_calibration()
    poses = random_board_poses(BOARD_SIM, 30, cal, np.random.default_rng(1))
    tilts = []
    for pose in poses:
        assert isinstance(pose, RigidTransform) and pose.name == "depth_from_board"
        pts = pose.apply(BOARD_SIM.object_points_m())
        assert np.all(cal.thermal.contains(cal.thermal.project(cal.thermal_from_depth.apply(pts))))
        assert np.all(cal.depth.contains(cal.depth.project(pts)))
        tilts.append(np.degrees(np.arccos(abs(pose.rotation[2, 2]))))
    assert 15.0 <= min(tilts) and max(tilts) <= 45.0 + 1e-9
