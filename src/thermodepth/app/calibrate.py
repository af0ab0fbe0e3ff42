"""``thermodepth calibrate`` and ``check-calibration``."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..board import BoardSpec
from ..calibrate import (
    CalibrationResult,
    discover_pairs,
    load_depth_intrinsics,
    plot_report,
    run_calibration,
    write_report_json,
)
from ..calibration import Calibration
from ..errors import FieldError
from ..progress import SILENT, Reporter


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
    depth_intrinsics, else 0.001); thermal_model, depth_model: distortion terms fitted;
    thermal_refine: thermal corner refinement; drop_outliers: fit again without the outlier
    images; report_dir: where calib_report.json and .png go (default: beside ``out``).
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
    fixed, scale = (None, None)
    if o.depth_intrinsics is not None:
        fixed, scale = load_depth_intrinsics(o.depth_intrinsics)
    if o.depth_scale_m is not None:
        if not (math.isfinite(o.depth_scale_m) and o.depth_scale_m > 0):
            raise FieldError("depth_scale_m", f"must be a finite number > 0, got {o.depth_scale_m}")
        scale = o.depth_scale_m
    listing = discover_pairs(o.pairs_dir)
    with reporter.task("detecting boards", len(listing.pairs)) as advance:
        result = run_calibration(
            listing,
            spec,
            depth_intrinsics=fixed,
            depth_scale_m=0.001 if scale is None else scale,
            thermal_model=o.thermal_model,
            depth_model=o.depth_model,
            thermal_refine=o.thermal_refine,
            drop_outliers=o.drop_outliers,
            progress=advance,
        )
    result.calibration.save(o.out)
    reports = o.report_dir if o.report_dir is not None else o.out.parent
    write_report_json(result, reports / "calib_report.json")
    plot_report(result, reports / "calib_report.png")
    return CalibrateOutcome(
        result, (o.out, reports / "calib_report.json", reports / "calib_report.png")
    )
