"""The report files of a calibration: ``calib_report.json`` and ``calib_report.png``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..plotting import pyplot, save_figure
from ..schema import write_mapping
from .fit import outlier_limits_px
from .run import CalibrationResult


def write_report_json(result: CalibrationResult, path: str | Path) -> None:
    """``calib_report.json``: :meth:`CalibrationResult.report_dict`."""
    write_mapping(path, result.report_dict())


def plot_report(result: CalibrationResult, path: str | Path) -> None:
    """A PNG: per-image RMS errors (bars per camera, the outlier limits as dotted lines,
    outlier images shaded red) and the thermal image's coverage by detected corners (corners
    per cell of :func:`coverage_grid` as a heat map, the corners on top)."""
    plt = pyplot()
    names = [p.name for p in result.used]
    n = len(names)
    x = np.arange(n)
    fig, (ax0, ax1) = plt.subplots(
        1, 2, figsize=(13, 5.0), gridspec_kw={"width_ratios": [max(1.2, n / 12), 1]}
    )
    series = [
        ("depth", result.depth_fit.per_view_rms_px, "tab:blue"),
        ("thermal", result.thermal_fit.per_view_rms_px, "tab:orange"),
        ("stereo, thermal side", result.stereo.per_view_rms_px[:, 1], "tab:green"),
    ]
    limits = outlier_limits_px(result.errors_px)[[0, 1, 3]]  # the columns drawn
    width = 0.27
    for k, (label, values, color) in enumerate(series):
        ax0.bar(x + (k - 1) * width, values, width, label=label, color=color)
        ax0.axhline(limits[k], color=color, linestyle=":", linewidth=1.2)
    top = max(max(float(np.max(v)) for _, v, _ in series), float(np.max(limits))) * 1.3
    for i in np.flatnonzero(result.outliers):
        ax0.axvspan(x[i] - 0.45, x[i] + 0.45, color="red", alpha=0.12)
        ax0.text(x[i], top * 0.8, "outlier", ha="center", color="red", fontsize=8, rotation=90)
    ax0.plot([], [], ":", color="grey", label="outlier limit")
    ax0.set_xticks(x, names, rotation=60, ha="right", fontsize=7)
    ax0.set_xlim(-0.6, n - 0.4)
    ax0.set_ylabel("RMS reprojection error, px")
    ax0.set_ylim(0, top)
    ax0.set_title(
        f"RMS per image (all: depth {result.depth_fit.rms_px:.3f}, thermal "
        f"{result.thermal_fit.rms_px:.3f}, stereo {result.stereo.rms_px:.3f} px)",
        fontsize=9,
    )
    ax0.legend(fontsize=7, loc="upper left", ncol=4)

    t = result.calibration.thermal
    cov = result.thermal_coverage
    im = ax1.imshow(
        cov,
        cmap="magma",
        extent=(-0.5, t.width - 0.5, t.height - 0.5, -0.5),
        interpolation="nearest",
    )
    pts = np.concatenate(result.thermal_points)
    ax1.plot(pts[:, 0], pts[:, 1], ".", color="cyan", markersize=1.5, alpha=0.6)
    ax1.plot([t.cx], [t.cy], "+", color="lime", markersize=12, label="principal point")
    ax1.set_xlim(-0.5, t.width - 0.5)
    ax1.set_ylim(t.height - 0.5, -0.5)
    ax1.set_xlabel("thermal u, px")
    ax1.set_ylabel("thermal v, px")
    ax1.set_title(
        f"thermal image coverage: {np.mean(cov > 0):.0%} of cells hold corners\n"
        f"baseline {result.stereo.baseline_m * 1000:.1f} mm, rotation "
        f"{result.stereo.rotation_deg:.2f} deg",
        fontsize=9,
    )
    ax1.legend(fontsize=7, loc="lower right")
    fig.colorbar(im, ax=ax1, label="corners per cell", fraction=0.035)
    save_figure(fig, path, dpi=110)
