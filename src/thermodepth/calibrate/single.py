"""One camera's intrinsics from single views of a board (``calibrate-camera``).

The good practice for a 160x120 thermal camera: many thermal views for its intrinsics (each
pose of the board constrains the focal length and principal point; a thermal camera's small
image needs many of them), then fewer pairs with the depth camera for the rigid transform
(``calibrate --thermal-intrinsics``). Views need no partner image, so they are quick to take.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from ..board import BoardSpec
from ..calibration import camera_dict
from ..errors import FieldError, InputError
from ..progress import Progress
from .detect import REFINE_METHODS
from .discover import DEPTH_ROLES
from .fit import (
    DISTORTION_MODELS,
    OUTLIER_MAD_K,
    OUTLIER_MEDIAN_RATIO,
    CameraFit,
    calibrate_camera,
    camera_report,
    coverage_grid,
    fit_warnings,
    flag_outliers,
    outlier_limits_px,
)
from .images import IMAGE_SUFFIXES, load_image
from .run import MIN_PAIRS, check_sizes, detect_view, image_size

FloatArray = NDArray[np.float64]
Camera = Literal["thermal", "depth"]

_ROLE = {
    "thermal": re.compile(r"(.+_thermal|right.*)", re.IGNORECASE),
    "depth": re.compile(rf"(.+_({'|'.join(DEPTH_ROLES)})|left.*)", re.IGNORECASE),
}


def as_camera(name: str) -> Camera:
    """``thermal`` or ``depth``; FieldError (``camera``) otherwise."""
    if name == "thermal":
        return "thermal"
    if name == "depth":
        return "depth"
    raise FieldError("camera", f"unknown {name!r}; choose thermal or depth")


def discover_images(folder: str | Path, camera: Camera) -> tuple[Path, ...]:
    """The images of one camera in ``folder``, sorted: those named as that camera's in a
    folder of pairs (``*_thermal``, ``right*``; ``*_ir``, ``*_color``, ``*_rgb``, ``left*``)
    when there are any, else every image. InputError when there is none."""
    path = Path(folder)
    if not path.is_dir():
        raise InputError(f"{path}: not a folder of images")
    images = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
    if not images:
        raise InputError(f"{path}: no images ({', '.join(IMAGE_SUFFIXES)})")
    named = [p for p in images if _ROLE[camera].fullmatch(p.stem)]
    return tuple(named or images)


@dataclass(frozen=True)
class SkippedImage:
    """An image left out, and why (unreadable, no board, a larger board)."""

    path: Path
    reason: str


@dataclass(frozen=True, eq=False)
class CameraResult:
    """What :func:`run_camera_calibration` found: the fit, the images used, skipped and
    dropped, and the detections (for coverage)."""

    camera: Camera
    board: BoardSpec
    fit: CameraFit
    images_found: int
    used: tuple[Path, ...]
    points: tuple[FloatArray, ...]
    dropped: tuple[Path, ...]
    skipped: tuple[SkippedImage, ...]

    @cached_property
    def outliers(self) -> NDArray[np.bool_]:
        """The used images :func:`~.fit.flag_outliers` flags."""
        return flag_outliers(self.fit.per_view_rms_px)

    @property
    def coverage(self) -> NDArray[np.int64]:
        intr = self.fit.intrinsics
        return coverage_grid(np.concatenate(self.points), intr.width, intr.height)

    @cached_property
    def warnings(self) -> tuple[str, ...]:
        """What the user should know: poor coverage, few views, outlier images."""
        views = ("views", "views", "20-50")
        names = [p.name for p in self.used]
        return fit_warnings(self.coverage, "the image", names, self.outliers, 15, views)

    def report_dict(self) -> dict[str, Any]:
        """All figures of the report, JSON-ready (``calib_report.json``)."""
        fit = self.fit
        cov = self.coverage
        return {
            "camera": self.camera,
            "board": str(self.board),
            "square_m": self.board.spacing_m,
            "images_found": self.images_found,
            "images_used": len(self.used),
            "rms_px": fit.rms_px,
            "intrinsics": camera_dict(fit.intrinsics),
            "fit": camera_report(fit),
            "outlier_rule": (
                f"per-image RMS > max(median + {OUTLIER_MAD_K:g} x 1.4826 x MAD, "
                f"{OUTLIER_MEDIAN_RATIO:g} x median)"
            ),
            "outlier_limit_px": float(outlier_limits_px(fit.per_view_rms_px)[0]),
            "per_image": [
                {"file": p.name, "rms_px": float(e), "outlier": bool(o)}
                for p, e, o in zip(self.used, fit.per_view_rms_px, self.outliers, strict=True)
            ],
            "dropped_outliers": [p.name for p in self.dropped],
            "coverage": {"fraction": float(np.mean(cov > 0)), "cells": cov.tolist()},
            "skipped": [{"file": str(s.path), "reason": s.reason} for s in self.skipped],
            "warnings": list(self.warnings),
        }


def run_camera_calibration(
    images: str | Path | tuple[Path, ...],
    board: BoardSpec,
    camera: Camera = "thermal",
    model: str | None = None,
    refine: str | None = None,
    drop_outliers: bool = False,
    min_images: int = MIN_PAIRS,
    progress: Progress | None = None,
) -> CameraResult:
    """One camera's intrinsics from single views of ``board``.

    images: a folder (:func:`discover_images`) or the image files; camera: ``thermal``
    (images stretched by percentiles, false-colour images turned back into levels) or
    ``depth`` (the depth camera's IR or colour images); model: the distortion terms
    (:data:`~.fit.DISTORTION_MODELS`; default ``no-k3`` for thermal, ``radial`` for depth);
    refine: corner refinement (default ``homography`` for thermal, ``cornersubpix`` for
    depth); drop_outliers: fit again without the outlier images.

    Unreadable images, images without the board and boards larger than ``board`` are skipped
    with the reason; fewer than ``min_images`` usable views, or image sizes that change,
    stop with one InputError line.
    """
    thermal = camera == "thermal"
    model = model or ("no-k3" if thermal else "radial")
    refine = refine or ("homography" if thermal else "cornersubpix")
    if model not in DISTORTION_MODELS:
        raise FieldError("model", f"unknown {model!r}; choose from {', '.join(DISTORTION_MODELS)}")
    if refine not in REFINE_METHODS:
        raise FieldError("refine", f"unknown {refine!r}; choose from {', '.join(REFINE_METHODS)}")
    paths = images if isinstance(images, tuple) else discover_images(images, camera)
    skipped: list[SkippedImage] = []
    loaded: list[tuple[Path, NDArray[Any]]] = []
    for path in paths:  # all read first: a change of size stops before the slow detection
        try:
            loaded.append((path, load_image(path, thermal)))
        except InputError as exc:
            skipped.append(SkippedImage(path, str(exc)))
    size = check_sizes({p: image_size(img) for p, img in loaded}, camera) if loaded else (0, 0)
    found: list[tuple[Path, FloatArray]] = []
    for path, img in loaded:
        det, edges = detect_view(img, board, thermal, refine)
        if det is None:
            skipped.append(SkippedImage(path, f"no {board} found"))
        elif edges:
            skipped.append(
                SkippedImage(path, f"the pattern goes on past the edge ({', '.join(edges)})")
            )
        else:
            found.append((path, det.points_px))
        if progress:
            progress(1)
    skipped.sort(key=lambda s: paths.index(s.path))
    if len(found) < min_images:
        why = "; ".join(f"{s.path.name}: {s.reason}" for s in skipped[:3])
        more = f" and {len(skipped) - 3} more" if len(skipped) > 3 else ""
        raise InputError(
            f"only {len(found)} usable {camera} views of {len(paths)} (need at least "
            f"{min_images})"
            + (f": {why}{more}" if why else "")
            + (
                f"; check --board: {board} counts inner corners, columns x rows"
                if not found
                else ""
            )
        )

    def fit(rows: list[tuple[Path, FloatArray]]) -> CameraFit:
        return calibrate_camera(
            [board.object_points_m() for _ in rows], [r[1] for r in rows], size, model
        )

    result = fit(found)
    dropped: tuple[Path, ...] = ()
    flags = flag_outliers(result.per_view_rms_px)
    if drop_outliers and flags.any():
        keep = [r for r, f in zip(found, flags, strict=True) if not f]
        dropped = tuple(r[0] for r, f in zip(found, flags, strict=True) if f)
        if len(keep) < min_images:
            raise FieldError(
                "drop_outliers",
                f"would leave {len(keep)} views (need at least {min_images}); "
                f"outliers: {', '.join(p.name for p in dropped)}",
            )
        found = keep
        result = fit(found)
    return CameraResult(
        camera,
        board,
        result,
        len(paths),
        tuple(p for p, _ in found),
        tuple(pts for _, pts in found),
        dropped,
        tuple(skipped),
    )
