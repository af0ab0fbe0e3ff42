"""``thermodepth calibrate``, ``calibrate-camera`` and ``check-calibration``."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from ..board import BoardSpec
from ..calibrate import (
    CalibrationResult,
    CameraResult,
    as_camera,
    discover_images,
    discover_pairs,
    load_intrinsics,
    plot_camera_report,
    plot_report,
    run_calibration,
    run_camera_calibration,
    write_report_json,
)
from ..calibration import Calibration, camera_dict, parse_output
from ..errors import FieldError
from ..progress import SILENT, Reporter
from ..schema import write_mapping


def calibration_summary(cal: Calibration) -> dict[str, Any]:
    """Human-sized facts about a calibration: sizes, FOVs, baseline mm, rotation deg, and the
    % of the depth image the thermal camera sees at 0.5, 1, 2 and 5 m."""
    return {
        "depth": f"{cal.depth.width}x{cal.depth.height}",
        "thermal": f"{cal.thermal.width}x{cal.thermal.height}",
        "depth_hfov_deg": round(cal.depth.hfov_deg, 2),
        "thermal_hfov_deg": round(cal.thermal.hfov_deg, 2),
        "depth_scale_m": cal.depth_scale_m,
        "baseline_mm": round(cal.baseline_m * 1000, 3),
        "rotation_deg": round(cal.thermal_from_depth.angle_deg, 4),
        "shared_view_pct": ", ".join(f"{z:g} m: {100 * f:.0f}" for z, f in cal.shared_view.items()),
    }


def check_calibration(path: Path) -> dict[str, Any]:
    """Validate a calibration file (one InputError line when it is bad) and summarise it."""
    return calibration_summary(Calibration.load(path))


@dataclass(frozen=True)
class CalibrateOptions:
    """A stereo calibration from board captures.

    pairs_dir: the folder of image pairs; board: ``checkerboard:COLSxROWS`` (inner corners)
    or ``circles:COLSxROWS``; square_m: the square size (grid step), metres; out: the
    calibration file to write; depth_intrinsics: hold the depth camera's intrinsics fixed (a
    calibration file or a camera's fields); depth_scale_m: the depth unit (default: from
    depth_intrinsics, else 0.001); thermal_intrinsics: hold the thermal camera's intrinsics
    fixed (``calibrate-camera``'s file, or a calibration file); thermal_model, depth_model:
    distortion terms fitted;
    thermal_refine: thermal corner refinement; drop_outliers: fit again without the outlier
    images; report_dir: where calib_report.json and .png go (default: beside ``out``);
    thermal_output: what the thermal camera's pixels are, written as ``thermal.output``
    (:func:`~thermodepth.calibration.parse_output`: ``counts``, ``kelvin:0.01``, ...).
    """

    pairs_dir: Path
    square_m: float
    board: str = "checkerboard:9x6"
    out: Path = Path("calib.yaml")
    depth_intrinsics: Path | None = None
    depth_scale_m: float | None = None
    thermal_model: str = "no-k3"
    depth_model: str = "radial"
    thermal_refine: str = "homography"
    drop_outliers: bool = False
    report_dir: Path | None = None
    thermal_intrinsics: Path | None = None
    thermal_output: str = "counts"


@dataclass(frozen=True)
class CalibrateOutcome:
    """A calibration run and the files it wrote (calibration, report JSON, report PNG)."""

    result: CalibrationResult
    files: tuple[Path, ...]


def calibrate(options: CalibrateOptions, reporter: Reporter = SILENT) -> CalibrateOutcome:
    """Calibrate the depth + thermal pair from board captures and write the calibration and
    its report; bad input raises an InputError (FieldError for an option)."""
    o = options
    spec = BoardSpec.parse(o.board, o.square_m)
    output = parse_output(o.thermal_output)
    fixed, scale = (None, None)
    if o.depth_intrinsics is not None:
        fixed, scale = load_intrinsics(o.depth_intrinsics, "depth")
    if o.depth_scale_m is not None:
        if not (math.isfinite(o.depth_scale_m) and o.depth_scale_m > 0):
            raise FieldError("depth_scale_m", f"must be a finite number > 0, got {o.depth_scale_m}")
        scale = o.depth_scale_m
    thermal = (
        None
        if o.thermal_intrinsics is None
        else load_intrinsics(o.thermal_intrinsics, "thermal")[0]
    )
    listing = discover_pairs(o.pairs_dir)
    with reporter.task("detecting boards", len(listing.pairs)) as advance:
        result = run_calibration(
            listing,
            spec,
            depth_intrinsics=fixed,
            depth_scale_m=0.001 if scale is None else scale,
            thermal_model=o.thermal_model,
            thermal_intrinsics=thermal,
            depth_model=o.depth_model,
            thermal_refine=o.thermal_refine,
            drop_outliers=o.drop_outliers,
            progress=advance,
        )
    result = replace(result, calibration=replace(result.calibration, thermal_output=output))
    result.calibration.save(o.out)
    files = _report_files(o.out, o.report_dir)
    write_report_json(result, files[1])
    plot_report(result, files[2])
    return CalibrateOutcome(result, files)


def _report_files(out: Path, report_dir: Path | None) -> tuple[Path, Path, Path]:
    """The output, and ``calib_report.json`` and ``.png`` in ``report_dir`` (default: beside
    the output)."""
    reports = report_dir if report_dir is not None else out.parent
    return out, reports / "calib_report.json", reports / "calib_report.png"


@dataclass(frozen=True)
class CameraOptions:
    """One camera's intrinsics from single views of a board.

    images_dir: the folder of views (in a folder of pairs, the camera's own images);
    square_m, board: as for :class:`CalibrateOptions`; out: the camera file to write (its
    fields: width, height, fx, fy, cx, cy, distortion); camera: ``thermal`` or ``depth``;
    model: distortion terms (default: no-k3 thermal, radial depth); refine: corner
    refinement (default: homography thermal, cornersubpix depth); drop_outliers, report_dir:
    as for :class:`CalibrateOptions`.
    """

    images_dir: Path
    square_m: float
    board: str = "checkerboard:9x6"
    out: Path = Path("thermal.yaml")
    camera: str = "thermal"
    model: str | None = None
    refine: str | None = None
    drop_outliers: bool = False
    report_dir: Path | None = None


@dataclass(frozen=True)
class CameraOutcome:
    """A single-camera calibration and the files it wrote (camera file, report JSON, PNG)."""

    result: CameraResult
    files: tuple[Path, ...]


def calibrate_camera(options: CameraOptions, reporter: Reporter = SILENT) -> CameraOutcome:
    """Calibrate one camera from single views and write its intrinsics and report; bad
    input raises an InputError (FieldError for an option)."""
    o = options
    camera = as_camera(o.camera)
    spec = BoardSpec.parse(o.board, o.square_m)
    images = discover_images(o.images_dir, camera)
    with reporter.task("detecting boards", len(images)) as advance:
        result = run_camera_calibration(
            images, spec, camera, o.model, o.refine, o.drop_outliers, progress=advance
        )
    files = _report_files(o.out, o.report_dir)
    write_mapping(o.out, camera_dict(result.fit.intrinsics))
    write_report_json(result, files[1])
    plot_camera_report(result, files[2])
    return CameraOutcome(result, files)
