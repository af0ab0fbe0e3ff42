"""Fitting the cameras to board views: one camera's intrinsics (Zhang's method), poses with
given intrinsics, the stereo transform, outlier images and coverage."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from ..camera import Intrinsics, RigidTransform
from ..errors import InputError

FloatArray = NDArray[np.float64]

DISTORTION_MODELS: dict[str, int] = {
    # k1, k2, p1, p2, k3: OpenCV's default
    "full": 0,
    # k1, k2, p1, p2: the thermal camera's default. A 160x120 view rarely has board corners
    # past r = 0.5 (normalised), where k3 r^6 is a few % of k1 r^2: k3 is then fitted to noise
    # and bends the image corners (simulated rig, 25 poses, 10 seeds: registration off by up
    # to 0.34 px with k3, 0.29 px without). Tangential terms of a few 1e-4 are small in
    # pixels, but leaving them out moves the principal point by ~0.2 px even with perfect
    # corners, a ~0.09 deg rotation error (docs/calibration.md).
    "no-k3": cv2.CALIB_FIX_K3,
    # k1, k2: the depth camera's default. Its board views sit inside the thermal camera's
    # narrower field, the middle of its image, where higher terms cannot be told apart (a D435
    # IR stream is rectified: its true distortion is zero).
    "radial": cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
    # pinhole
    "none": cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
}
"""Which distortion coefficients ``calibrate_camera`` fits; the others are held at zero."""


@dataclass(frozen=True, eq=False)
class CameraFit:
    """One camera's intrinsics from the board views, or given and held fixed.

    rms_px: RMS reprojection error over all points; per_view_rms_px (n,): per image;
    rvecs, tvecs: ``camera_from_board`` per view (Rodrigues rotation and translation as (3,)
    arrays, metres);
    model: distortion model name (:data:`DISTORTION_MODELS`) or ``"fixed"``;
    std_px: standard deviations of fx, fy, cx, cy from OpenCV (NaN when fixed).
    """

    intrinsics: Intrinsics
    rms_px: float
    per_view_rms_px: FloatArray
    rvecs: tuple[FloatArray, ...]
    tvecs: tuple[FloatArray, ...]
    model: str
    std_px: FloatArray = field(default_factory=lambda: np.full(4, np.nan))


def _f32(points: FloatArray) -> NDArray[np.float32]:
    return np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 1, points.shape[-1])


def _view_rms(
    obj: FloatArray, img: FloatArray, rvec: FloatArray, tvec: FloatArray, intr: Intrinsics
) -> float:
    proj, _ = cv2.projectPoints(obj, rvec, tvec, intr.matrix, intr.distortion.copy())
    return float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))


def calibrate_camera(
    object_points: Sequence[FloatArray],
    image_points: Sequence[FloatArray],
    image_size: tuple[int, int],
    model: str = "full",
) -> CameraFit:
    """Intrinsics of one camera from board views (``cv2.calibrateCamera``, Zhang's method).

    object_points: per view (N, 3) board points in metres; image_points: per view (N, 2)
    pixels; image_size: (width, height); model: which distortion terms to fit
    (:data:`DISTORTION_MODELS`).
    """
    if model not in DISTORTION_MODELS:
        raise InputError(
            f"unknown distortion model {model!r}; choose from {list(DISTORTION_MODELS)}"
        )
    rms, k, dist, rvecs, tvecs, std_intr, _, per_view = cv2.calibrateCameraExtended(
        [_f32(o) for o in object_points],
        [_f32(p) for p in image_points],
        image_size,
        np.eye(3),
        np.zeros(5),
        flags=DISTORTION_MODELS[model],
    )
    d = np.zeros(5)
    flat = np.asarray(dist, dtype=np.float64).ravel()
    d[: min(5, flat.size)] = flat[:5]
    w, h = image_size
    intr = Intrinsics(w, h, float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]), d)
    return CameraFit(
        intr,
        float(rms),
        np.asarray(per_view, dtype=np.float64).ravel(),
        tuple(np.asarray(r, np.float64).ravel() for r in rvecs),
        tuple(np.asarray(t, np.float64).ravel() for t in tvecs),
        model,
        np.asarray(std_intr, dtype=np.float64).ravel()[:4],
    )


def fixed_camera_fit(
    intrinsics: Intrinsics,
    object_points: Sequence[FloatArray],
    image_points: Sequence[FloatArray],
) -> CameraFit:
    """Board poses and reprojection errors of a camera whose intrinsics are given
    (``cv2.solvePnP``, iterative, per view); shapes as :func:`calibrate_camera`."""
    rvecs, tvecs, per_view, sq = [], [], [], []
    for obj, img in zip(object_points, image_points, strict=True):
        ok, rvec, tvec = cv2.solvePnP(
            obj.astype(np.float64),
            img.astype(np.float64),
            intrinsics.matrix,
            intrinsics.distortion.copy(),
        )
        if not ok:  # pragma: no cover - solvePnP fails only on degenerate input
            raise InputError("solvePnP failed for a view with the given depth intrinsics")
        rvec = np.asarray(rvec, np.float64).ravel()
        tvec = np.asarray(tvec, np.float64).ravel()
        rvecs.append(rvec)
        tvecs.append(tvec)
        e = _view_rms(obj, img, rvec, tvec, intrinsics)
        per_view.append(e)
        sq.append(e * e * len(obj))
    n = sum(len(o) for o in object_points)
    return CameraFit(
        intrinsics,
        float(np.sqrt(sum(sq) / n)),
        np.array(per_view),
        tuple(rvecs),
        tuple(tvecs),
        "fixed",
    )


@dataclass(frozen=True, eq=False)
class StereoFit:
    """``thermal_from_depth`` from ``cv2.stereoCalibrate`` with fixed intrinsics.

    rms_px: OpenCV's RMS over both cameras' points; per_view_rms_px (n, 2): per pair, depth
    camera then thermal camera.
    """

    thermal_from_depth: RigidTransform
    rms_px: float
    per_view_rms_px: FloatArray

    @property
    def baseline_m(self) -> float:
        """Distance between the optical centres, metres."""
        return self.thermal_from_depth.distance_m

    @property
    def rotation_deg(self) -> float:
        """Angle of the rotation between the cameras, degrees."""
        return self.thermal_from_depth.angle_deg


def stereo_calibrate(
    object_points: Sequence[FloatArray],
    depth_points: Sequence[FloatArray],
    thermal_points: Sequence[FloatArray],
    depth: Intrinsics,
    thermal: Intrinsics,
) -> StereoFit:
    """The rigid transform p_thermal = R p_depth + t (t in the board's units: metres) with
    both cameras' intrinsics fixed (``cv2.stereoCalibrate``, ``CALIB_FIX_INTRINSIC``).

    object_points: per pair (N, 3) metres; depth_points / thermal_points: per pair (N, 2) px
    in matching order (:func:`match_order`).
    """
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-7)
    out = cv2.stereoCalibrateExtended(
        [_f32(o) for o in object_points],
        [_f32(p) for p in depth_points],
        [_f32(p) for p in thermal_points],
        depth.matrix,
        depth.distortion.copy(),
        thermal.matrix,
        thermal.distortion.copy(),
        (depth.width, depth.height),
        np.eye(3),
        np.zeros((3, 1)),
        flags=cv2.CALIB_FIX_INTRINSIC,
        criteria=crit,
    )
    rms, r, t, per_view = out[0], out[5], out[6], out[11]
    transform = RigidTransform(
        np.asarray(r, np.float64), np.asarray(t, np.float64).ravel(), "thermal", "depth"
    )
    return StereoFit(transform, float(rms), np.asarray(per_view, dtype=np.float64).reshape(-1, 2))


# -- outliers and coverage --------------------------------------------------------------------

OUTLIER_MAD_K = 3.0
OUTLIER_MEDIAN_RATIO = 2.0


def flag_outliers(errors_px: FloatArray) -> NDArray[np.bool_]:
    """Outlier images by their RMS reprojection error, per column (camera) of
    ``errors_px`` (n,) or (n, k); True where any column flags the row.

    Rule: e > median + 3 x 1.4826 x MAD (MAD scaled to a normal distribution's sigma) and
    e > 2 x median (``OUTLIER_MEDIAN_RATIO``): the first flags what is far off the spread of
    the others, the second keeps images that are only a little worse when all errors are
    alike (MAD near 0)."""
    e = np.asarray(errors_px, dtype=np.float64)
    e = e[:, None] if e.ndim == 1 else e
    out: NDArray[np.bool_] = np.any(e > outlier_limits_px(e), axis=1)
    return out


def fit_warnings(
    coverage: NDArray[np.int64],
    image: str,
    used: Sequence[str],
    outliers: NDArray[np.bool_],
    fewest: int,
    views: tuple[str, str, str],
) -> tuple[str, ...]:
    """What the user should know of a fit: the board covering under half of ``image`` (the
    cells of ``coverage`` it reached), fewer than ``fewest`` images used (``used``: their
    names), the ``outliers`` among them. ``views``: what the images are called in the
    advice (used, moved, and how many fit better: ``("pairs", "poses", "15-25")``)."""
    counted, moved, better = views
    warn = []
    cov = float(np.mean(coverage > 0))
    if cov < 0.5:
        warn.append(
            f"the board covered {cov:.0%} of {image}: add {moved} near its edges and "
            "corners, or distortion is extrapolated there"
        )
    if len(used) < fewest:
        warn.append(f"only {len(used)} {counted} used: {better} well-spread {moved} fit better")
    if outliers.any():
        names = ", ".join(name for name, f in zip(used, outliers, strict=True) if f)
        warn.append(f"outlier images: {names} (--drop-outliers fits without them)")
    return tuple(warn)


def per_view_errors_px(depth: CameraFit, thermal: CameraFit, stereo: StereoFit) -> FloatArray:
    """Per-image RMS reprojection errors (n, 4), pixels: each camera's own fit, then the
    stereo fit's depth and thermal sides (the columns the outlier rule judges)."""
    return np.column_stack([depth.per_view_rms_px, thermal.per_view_rms_px, stereo.per_view_rms_px])


def outlier_limits_px(errors_px: FloatArray) -> FloatArray:
    """The thresholds of :func:`flag_outliers` per column, pixels."""
    e = np.asarray(errors_px, dtype=np.float64)
    if e.ndim == 1:
        e = e[:, None]
    med = np.median(e, axis=0)
    mad = 1.4826 * np.median(np.abs(e - med), axis=0)
    out: FloatArray = np.maximum(med + OUTLIER_MAD_K * mad, OUTLIER_MEDIAN_RATIO * med)
    return out


def coverage_grid(
    points_px: FloatArray, width: int, height: int, cols: int = 8
) -> NDArray[np.int64]:
    """Count of detected points per cell of a grid over the image, (rows, cols).

    The grid has ``cols`` columns and round(cols x height / width) rows (8 x 6 for 4:3):
    cells of 20 x 20 px on a 160x120 thermal image.
    """
    rows = max(1, round(cols * height / width))
    pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
    counts, _, _ = np.histogram2d(
        pts[:, 1], pts[:, 0], bins=(rows, cols), range=((-0.5, height - 0.5), (-0.5, width - 0.5))
    )
    return counts.astype(np.int64)


def camera_report(fit: CameraFit) -> dict[str, Any]:
    intr = fit.intrinsics
    cx0, cy0 = (intr.width - 1) / 2.0, (intr.height - 1) / 2.0
    return {
        "size": [intr.width, intr.height],
        "model": fit.model,
        "rms_px": fit.rms_px,
        "fx": intr.fx,
        "fy": intr.fy,
        "cx": intr.cx,
        "cy": intr.cy,
        "distortion": intr.distortion.tolist(),
        "std_fx_fy_cx_cy_px": [None if np.isnan(v) else float(v) for v in fit.std_px],
        "principal_point_offset_px": [intr.cx - cx0, intr.cy - cy0],
        "hfov_deg": intr.hfov_deg,
    }
