"""A calibration run: the pairs of a folder -> detections -> fits -> the calibration and the
figures of its report (:class:`CalibrationResult`)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from ..board import BoardSpec
from ..calibration import (
    Calibration,
    CameraSchema,
    DepthCameraSchema,
    ThermalCameraSchema,
    intrinsics_of,
)
from ..camera import Intrinsics
from ..errors import FieldError, InputError
from ..progress import Progress
from ..schema import read_mapping, validated
from .detect import REFINE_METHODS, Detection, detect_board, grid_continues, match_order
from .discover import ImagePair, PairListing, discover_pairs
from .fit import (
    DISTORTION_MODELS,
    OUTLIER_MAD_K,
    OUTLIER_MEDIAN_RATIO,
    CameraFit,
    StereoFit,
    calibrate_camera,
    camera_report,
    coverage_grid,
    fit_warnings,
    fixed_camera_fit,
    flag_outliers,
    outlier_limits_px,
    per_view_errors_px,
    stereo_calibrate,
)
from .images import load_image

FloatArray = NDArray[np.float64]

MIN_PAIRS = 6
"""Fewest usable pairs to calibrate with: each view of a planar board gives 2 constraints on
the intrinsics, and a fit of 4 + distortion parameters needs several well-spread views;
OpenCV's documentation recommends 10-20."""


SkipKind = Literal["unreadable", "no board", "larger board"]


@dataclass(frozen=True)
class SkippedPair:
    """A pair left out: of which kind (``"unreadable"``, ``"no board"``, ``"larger board"``:
    a board with more corners than asked for), why in words, and which files are to blame."""

    pair: ImagePair
    kind: SkipKind
    reason: str
    files: tuple[Path, ...]


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """Everything :func:`run_calibration` found: the calibration, the fits, the pairs used,
    skipped and dropped, the outlier flags and the detections (for coverage)."""

    calibration: Calibration
    board: BoardSpec
    depth_fit: CameraFit
    thermal_fit: CameraFit
    stereo: StereoFit
    used: tuple[ImagePair, ...]
    depth_points: tuple[FloatArray, ...]
    thermal_points: tuple[FloatArray, ...]
    thermal_inverted: tuple[bool, ...]
    dropped: tuple[ImagePair, ...]
    skipped: tuple[SkippedPair, ...]
    unmatched: tuple[tuple[Path, str], ...]

    @cached_property
    def errors_px(self) -> FloatArray:
        """Per-image RMS reprojection errors (n, 4): depth, thermal, stereo depth and thermal
        sides (:func:`per_view_errors_px`)."""
        return per_view_errors_px(self.depth_fit, self.thermal_fit, self.stereo)

    @cached_property
    def outliers(self) -> NDArray[np.bool_]:
        """The used images :func:`flag_outliers` flags."""
        return flag_outliers(self.errors_px)

    @cached_property
    def warnings(self) -> tuple[str, ...]:
        """What the user should know: poor thermal coverage, few pairs, outlier images."""
        cov, views = self.thermal_coverage, ("pairs", "poses", "15-25")
        names = [p.name for p in self.used]
        return fit_warnings(cov, "the thermal image", names, self.outliers, 10, views)

    def per_image(self) -> list[dict[str, Any]]:
        """Per used pair: name, depth / thermal RMS (own fits), stereo RMS per camera,
        outlier flag."""
        rows = []
        for i, pair in enumerate(self.used):
            rows.append(
                {
                    "name": pair.name,
                    "depth_file": pair.depth_path.name,
                    "thermal_file": pair.thermal_path.name,
                    "depth_rms_px": float(self.depth_fit.per_view_rms_px[i]),
                    "thermal_rms_px": float(self.thermal_fit.per_view_rms_px[i]),
                    "stereo_depth_rms_px": float(self.stereo.per_view_rms_px[i, 0]),
                    "stereo_thermal_rms_px": float(self.stereo.per_view_rms_px[i, 1]),
                    "thermal_inverted": bool(self.thermal_inverted[i]),
                    "outlier": bool(self.outliers[i]),
                }
            )
        return rows

    @property
    def thermal_coverage(self) -> NDArray[np.int64]:
        t = self.calibration.thermal
        return coverage_grid(np.concatenate(self.thermal_points), t.width, t.height)

    @property
    def depth_coverage(self) -> NDArray[np.int64]:
        d = self.calibration.depth
        return coverage_grid(np.concatenate(self.depth_points), d.width, d.height)

    def report_dict(self) -> dict[str, Any]:
        """All figures of the report, JSON-ready (pixels, millimetres, degrees)."""
        cal = self.calibration
        t = cal.thermal_from_depth
        cov_t, cov_d = self.thermal_coverage, self.depth_coverage
        return {
            "board": str(self.board),
            "square_m": self.board.spacing_m,
            "pairs_used": len(self.used),
            "depth_camera": camera_report(self.depth_fit),
            "thermal_camera": camera_report(self.thermal_fit),
            "stereo": {
                "rms_px": self.stereo.rms_px,
                "baseline_mm": self.stereo.baseline_m * 1000.0,
                "translation_mm": (t.translation_m * 1000.0).tolist(),
                "rotation_deg": self.stereo.rotation_deg,
                "rotation": t.rotation.tolist(),
            },
            "outlier_rule": (
                f"per-image RMS > max(median + {OUTLIER_MAD_K:g} x 1.4826 x MAD, "
                f"{OUTLIER_MEDIAN_RATIO:g} x median), per camera, own fits and stereo"
            ),
            "outlier_limits_px": dict(
                zip(
                    ["depth", "thermal", "stereo_depth", "stereo_thermal"],
                    outlier_limits_px(self.errors_px).tolist(),
                    strict=True,
                )
            ),
            "per_image": self.per_image(),
            "dropped_outliers": [p.name for p in self.dropped],
            "coverage": {
                "thermal_fraction": float(np.mean(cov_t > 0)),
                "thermal_cells": cov_t.tolist(),
                "depth_fraction": float(np.mean(cov_d > 0)),
                "depth_cells": cov_d.tolist(),
            },
            "skipped": [
                {"name": s.pair.name, "reason": s.reason, "files": [str(f) for f in s.files]}
                for s in self.skipped
            ],
            "unmatched": [{"file": str(p), "reason": r} for p, r in self.unmatched],
            "warnings": list(self.warnings),
        }


def load_intrinsics(path: str | Path, camera: str) -> tuple[Intrinsics, float | None]:
    """A camera's intrinsics to hold fixed, and its depth unit if the file has one.

    camera: ``"depth"`` or ``"thermal"``. Accepts a calibration file (its section of that
    camera is used) or a YAML/JSON file with just the camera's fields (width, height, fx,
    fy, cx, cy, distortion, optional depth_scale_m), as ``calibrate-camera`` writes them.
    """
    data = read_mapping(path)
    nested = isinstance(data.get(camera), dict)
    section = data[camera] if nested else data
    schema: type[CameraSchema] = CameraSchema
    if "depth_scale_m" in section:
        schema = DepthCameraSchema
    elif camera == "thermal":  # a calibration file's thermal section may say its output
        schema = ThermalCameraSchema
    cam = validated(schema, section, str(path), f"{camera}." if nested else "")
    return intrinsics_of(cam), getattr(cam, "depth_scale_m", None)


def detect_view(
    image: NDArray[Any],
    board: BoardSpec,
    thermal: bool,
    refine: str,
    upscale: int | None = None,
    quick: bool = False,
) -> tuple[Detection | None, tuple[str, ...]]:
    """The board in one camera's image: its detection (None: not found; a thermal image is
    stretched, a depth camera's 8-bit image used as it is; ``quick``: the stream's search,
    :func:`~.detect.detect_board`) and the edges past which its pattern goes on (a board
    larger than ``board``: :func:`~.detect.grid_continues`)."""
    det = detect_board(image, board, True if thermal else None, upscale, refine, quick)
    if det is None or board.kind != "checkerboard":
        return det, ()
    return det, grid_continues(image, det.points_px, board)


def image_size(img: NDArray[Any]) -> tuple[int, int]:
    """(width, height) of an image (H, W)."""
    return (int(img.shape[1]), int(img.shape[0]))


def check_sizes(sizes: dict[Path, tuple[int, int]], camera: str) -> tuple[int, int]:
    """The one image size of a camera; InputError naming the files that differ."""
    counts = Counter(sizes.values())
    common, n_common = counts.most_common(1)[0]
    odd = [(p, s) for p, s in sizes.items() if s != common]
    if odd:
        shown = ", ".join(f"{p.name} is {s[0]}x{s[1]}" for p, s in odd[:3])
        more = f" and {len(odd) - 3} more" if len(odd) > 3 else ""
        raise InputError(
            f"{camera} image sizes differ: {shown}{more}, but {n_common} "
            f"{'is' if n_common == 1 else 'are'} {common[0]}x{common[1]}"
        )
    return common


def run_calibration(
    pairs: str | Path | PairListing,
    board: BoardSpec,
    depth_intrinsics: Intrinsics | None = None,
    depth_scale_m: float = 0.001,
    thermal_model: str = "no-k3",
    thermal_intrinsics: Intrinsics | None = None,
    depth_model: str = "radial",
    drop_outliers: bool = False,
    min_pairs: int = MIN_PAIRS,
    thermal_upscale: int | None = None,
    thermal_refine: str = "homography",
    depth_refine: str = "cornersubpix",
    progress: Progress | None = None,
) -> CalibrationResult:
    """Calibrate the pair from the image pairs of a folder (or what :func:`discover_pairs`
    found in one).

    board: the target (square size in metres: translation comes out in metres);
    depth_intrinsics: hold the depth camera's intrinsics fixed (else calibrated from its
    images); depth_scale_m: the depth unit written to the calibration file; thermal_model /
    depth_model: distortion terms to fit (:data:`DISTORTION_MODELS`); thermal_intrinsics:
    hold the thermal camera's intrinsics fixed (from ``calibrate-camera``: many single views
    fit a 160x120 camera better than the pairs alone); drop_outliers: fit again without the
    outlier images (:func:`flag_outliers`); min_pairs: fewest usable pairs; progress: called
    with 1 per pair examined.

    Unreadable images and pairs where one camera shows no board are skipped and listed.
    Raises InputError for fewer than ``min_pairs`` usable pairs (saying how many and why),
    image sizes that change within a camera, or fixed intrinsics of another image size.
    """
    for name, refine in (("thermal", thermal_refine), ("depth", depth_refine)):
        if refine not in REFINE_METHODS:
            raise FieldError(
                f"{name}_refine", f"unknown {refine!r}; choose from {', '.join(REFINE_METHODS)}"
            )
    for name, model in (("thermal", thermal_model), ("depth", depth_model)):
        if model not in DISTORTION_MODELS:
            raise FieldError(
                f"{name}_model", f"unknown {model!r}; choose from {', '.join(DISTORTION_MODELS)}"
            )
    listing = pairs if isinstance(pairs, PairListing) else discover_pairs(pairs)
    skipped: list[SkippedPair] = []
    # first read every image (cheap), so that a change of image size stops the run before
    # the slow detection
    loaded: list[tuple[ImagePair, NDArray[Any], NDArray[Any]]] = []
    depth_sizes: dict[Path, tuple[int, int]] = {}
    thermal_sizes: dict[Path, tuple[int, int]] = {}
    for pair in listing.pairs:
        images = []
        for path, thermal in ((pair.depth_path, False), (pair.thermal_path, True)):
            try:
                images.append(load_image(path, thermal))
            except InputError as exc:
                skipped.append(SkippedPair(pair, "unreadable", str(exc), (path,)))
                break
        else:
            depth_sizes[pair.depth_path] = image_size(images[0])
            thermal_sizes[pair.thermal_path] = image_size(images[1])
            loaded.append((pair, images[0], images[1]))
    depth_size = check_sizes(depth_sizes, "depth camera") if depth_sizes else (0, 0)
    thermal_size = check_sizes(thermal_sizes, "thermal") if thermal_sizes else (0, 0)
    for name, fixed, size in (
        ("depth", depth_intrinsics, depth_size),
        ("thermal", thermal_intrinsics, thermal_size),
    ):
        if fixed is not None and loaded and (fixed.width, fixed.height) != size:
            raise FieldError(
                f"{name}_intrinsics",
                f"size {fixed.width}x{fixed.height} does not match the {name} camera's "
                f"images ({size[0]}x{size[1]})",
            )
    if progress and len(loaded) < len(listing.pairs):
        progress(len(listing.pairs) - len(loaded))

    found: list[tuple[ImagePair, Detection, Detection]] = []
    for pair, depth_img, thermal_img in loaded:
        d, d_edges = detect_view(depth_img, board, False, depth_refine)
        t, t_edges = detect_view(thermal_img, board, True, thermal_refine, thermal_upscale)
        if d is None or t is None:
            missing = tuple(
                p for p, det in ((pair.depth_path, d), (pair.thermal_path, t)) if det is None
            )
            names = " and ".join(p.name for p in missing)
            skipped.append(SkippedPair(pair, "no board", f"no {board} found in {names}", missing))
        elif larger := [
            (p, e) for p, e in ((pair.depth_path, d_edges), (pair.thermal_path, t_edges)) if e
        ]:
            names = " and ".join(f"{p.name} ({', '.join(edges)})" for p, edges in larger)
            skipped.append(
                SkippedPair(
                    pair,
                    "larger board",
                    f"the pattern goes on past the edge of the {board} found in {names}",
                    tuple(p for p, _ in larger),
                )
            )
        else:
            t = Detection(
                match_order(d.points_px, t.points_px, board), t.inverted, t.upscale, t.method
            )
            found.append((pair, d, t))
        if progress:
            progress(1)
    skipped.sort(key=lambda sp: listing.pairs.index(sp.pair))
    if len(found) < min_pairs:
        raise InputError(
            _too_few_message(len(found), len(listing.pairs), min_pairs, skipped, listing, board)
        )

    def fit(
        rows: list[tuple[ImagePair, Detection, Detection]],
    ) -> tuple[CameraFit, CameraFit, StereoFit]:
        obj = [board.object_points_m() for _ in rows]
        dp = [r[1].points_px for r in rows]
        tp = [r[2].points_px for r in rows]
        if depth_intrinsics is None:
            dfit = calibrate_camera(obj, dp, depth_size, depth_model)
        else:
            dfit = fixed_camera_fit(depth_intrinsics, obj, dp)
        if thermal_intrinsics is None:
            tfit = calibrate_camera(obj, tp, thermal_size, thermal_model)
        else:
            tfit = fixed_camera_fit(thermal_intrinsics, obj, tp)
        sfit = stereo_calibrate(obj, dp, tp, dfit.intrinsics, tfit.intrinsics)
        return dfit, tfit, sfit

    rows = found
    dfit, tfit, sfit = fit(rows)
    flags = flag_outliers(per_view_errors_px(dfit, tfit, sfit))
    dropped: tuple[ImagePair, ...] = ()
    if drop_outliers and flags.any():
        keep = [r for r, f in zip(rows, flags, strict=True) if not f]
        dropped = tuple(r[0] for r, f in zip(rows, flags, strict=True) if f)
        if len(keep) < min_pairs:
            raise FieldError(
                "drop_outliers",
                f"would leave {len(keep)} pairs (need at least {min_pairs}); "
                f"outliers: {', '.join(p.name for p in dropped)}",
            )
        rows = keep
        dfit, tfit, sfit = fit(rows)

    calibration = Calibration(
        dfit.intrinsics, tfit.intrinsics, depth_scale_m, sfit.thermal_from_depth
    )
    return CalibrationResult(
        calibration=calibration,
        board=board,
        depth_fit=dfit,
        thermal_fit=tfit,
        stereo=sfit,
        used=tuple(r[0] for r in rows),
        depth_points=tuple(r[1].points_px for r in rows),
        thermal_points=tuple(r[2].points_px for r in rows),
        thermal_inverted=tuple(r[2].inverted for r in rows),
        dropped=dropped,
        skipped=tuple(skipped),
        unmatched=listing.unmatched,
    )


def _too_few_message(
    n_found: int,
    n_pairs: int,
    need: int,
    skipped: list[SkippedPair],
    listing: PairListing,
    board: BoardSpec,
) -> str:
    unreadable, no_board, larger = (
        [s.pair.name for s in skipped if s.kind == kind]
        for kind in ("unreadable", "no board", "larger board")
    )
    parts = []
    if no_board:
        parts.append(f"{len(no_board)} without a board in one or both images ({_names(no_board)})")
    if larger:
        parts.append(f"{len(larger)} where the board has more corners ({_names(larger)})")
    if larger or (n_found == 0 and len(no_board) >= 2):
        # a wrong size is more likely than bad captures
        counts = "inner corners" if board.kind == "checkerboard" else "circles"
        parts.append(f"check --board: {board} counts {counts}, columns x rows")
    if unreadable:
        parts.append(f"{len(unreadable)} with an unreadable image ({_names(unreadable)})")
    if listing.unmatched:
        parts.append(f"{len(listing.unmatched)} files not paired by name")
    reasons = "; ".join(parts) if parts else "capture more poses"
    return f"only {n_found} usable pairs of {n_pairs} (need at least {need}): {reasons}"


def _names(names: list[str], limit: int = 5) -> str:
    more = f" and {len(names) - limit} more" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more
