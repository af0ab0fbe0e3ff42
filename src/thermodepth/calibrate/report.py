"""The report files of a calibration: ``calib_report.json`` and ``calib_report.png``, for a
pair of cameras (``calibrate``) or one camera (``calibrate-camera``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..camera import Intrinsics
from ..plotting import pyplot, save_figure
from ..schema import write_mapping
from .fit import outlier_limits_px
from .run import CalibrationResult
from .single import CameraResult

Series = tuple[str, NDArray[np.float64], str, float]
"""A bar series: label, RMS error per image (px), colour, its outlier limit (px)."""


def write_report_json(result: CalibrationResult | CameraResult, path: str | Path) -> None:
    """``calib_report.json``: the result's ``report_dict()``."""
    write_mapping(path, result.report_dict())


def _errors_panel(
    ax: Any, names: list[str], series: list[Series], outliers: NDArray[np.bool_], title: str
) -> None:
    """Per-image RMS errors as bars per series, each outlier limit dotted, outlier images
    shaded red."""
    n = len(names)
    x = np.arange(n)
    width = 0.8 / len(series)
    for k, (label, values, color, limit) in enumerate(series):
        ax.bar(x + (k - (len(series) - 1) / 2) * width, values, width, label=label, color=color)
        ax.axhline(limit, color=color, linestyle=":", linewidth=1.2)
    top = max(max(float(np.max(v)), lim) for _, v, _, lim in series) * 1.3
    for i in np.flatnonzero(outliers):
        ax.axvspan(x[i] - 0.45, x[i] + 0.45, color="red", alpha=0.12)
        ax.text(x[i], top * 0.8, "outlier", ha="center", color="red", fontsize=8, rotation=90)
    ax.plot([], [], ":", color="grey", label="outlier limit")
    ax.set_xticks(x, names, rotation=60, ha="right", fontsize=7)
    ax.set_xlim(-0.6, n - 0.4)
    ax.set_ylabel("RMS reprojection error, px")
    ax.set_ylim(0, top)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="upper left", ncol=4)


def _coverage_panel(
    fig: Any, ax: Any, intr: Intrinsics, cells: NDArray[np.int64], points: NDArray[Any], title: str
) -> None:
    """The image's coverage by detected corners: corners per cell as a heat map, the corners
    and the principal point on top."""
    im = ax.imshow(
        cells,
        cmap="magma",
        extent=(-0.5, intr.width - 0.5, intr.height - 0.5, -0.5),
        interpolation="nearest",
    )
    ax.plot(points[:, 0], points[:, 1], ".", color="cyan", markersize=1.5, alpha=0.6)
    ax.plot([intr.cx], [intr.cy], "+", color="lime", markersize=12, label="principal point")
    ax.set_xlim(-0.5, intr.width - 0.5)
    ax.set_ylim(intr.height - 0.5, -0.5)
    ax.set_xlabel("u, px")
    ax.set_ylabel("v, px")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="lower right")
    fig.colorbar(im, ax=ax, label="corners per cell", fraction=0.035)


def _figure(n_images: int) -> tuple[Any, Any, Any]:
    plt = pyplot()
    fig, (ax0, ax1) = plt.subplots(
        1, 2, figsize=(13, 5.0), gridspec_kw={"width_ratios": [max(1.2, n_images / 12), 1]}
    )
    return fig, ax0, ax1


def plot_report(result: CalibrationResult, path: str | Path) -> None:
    """A PNG of a stereo calibration: per-image RMS errors (bars per camera, the outlier
    limits dotted, outlier images shaded red) and the thermal image's coverage by detected
    corners (:func:`~.fit.coverage_grid`)."""
    fig, ax0, ax1 = _figure(len(result.used))
    limits = outlier_limits_px(result.errors_px)
    series: list[Series] = [
        ("depth", result.depth_fit.per_view_rms_px, "tab:blue", float(limits[0])),
        ("thermal", result.thermal_fit.per_view_rms_px, "tab:orange", float(limits[1])),
        (
            "stereo, thermal side",
            result.stereo.per_view_rms_px[:, 1],
            "tab:green",
            float(limits[3]),
        ),
    ]
    _errors_panel(
        ax0,
        [p.name for p in result.used],
        series,
        result.outliers,
        f"RMS per image (all: depth {result.depth_fit.rms_px:.3f}, thermal "
        f"{result.thermal_fit.rms_px:.3f}, stereo {result.stereo.rms_px:.3f} px)",
    )
    cov = result.thermal_coverage
    _coverage_panel(
        fig,
        ax1,
        result.calibration.thermal,
        cov,
        np.concatenate(result.thermal_points),
        f"thermal image coverage: {np.mean(cov > 0):.0%} of cells hold corners\n"
        f"baseline {result.stereo.baseline_m * 1000:.1f} mm, rotation "
        f"{result.stereo.rotation_deg:.2f} deg",
    )
    save_figure(fig, path, dpi=110)


def plot_camera_report(result: CameraResult, path: str | Path) -> None:
    """A PNG of one camera's calibration: per-image RMS errors (the outlier limit dotted,
    outliers shaded red) and the image's coverage by detected corners."""
    fig, ax0, ax1 = _figure(len(result.used))
    fit = result.fit
    limit = float(outlier_limits_px(fit.per_view_rms_px)[0])
    _errors_panel(
        ax0,
        [p.name for p in result.used],
        [(result.camera, fit.per_view_rms_px, "tab:orange", limit)],
        result.outliers,
        f"RMS per image ({result.camera} camera, all: {fit.rms_px:.3f} px, "
        f"{len(result.used)} of {result.images_found} images)",
    )
    cov = result.coverage
    _coverage_panel(
        fig,
        ax1,
        fit.intrinsics,
        cov,
        np.concatenate(result.points),
        f"{result.camera} image coverage: {np.mean(cov > 0):.0%} of cells hold corners\n"
        f"fx {fit.intrinsics.fx:.2f}, fy {fit.intrinsics.fy:.2f} px",
    )
    save_figure(fig, path, dpi=110)
