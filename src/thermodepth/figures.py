"""Figures (matplotlib, PNG): registration error, the paper's Figs. 13 and 14."""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np
from numpy.typing import NDArray

from .compensation import CompensationModel, apply_to_table, by_vox
from .isotherms import ISOTHERM_RGB, IsothermRoi
from .lines import LineRoi
from .plotting import distinct_styles, pyplot, save_figure, temperature_rgb
from .registration import Reason
from .sweep import SweepTable

if TYPE_CHECKING:
    from .alarms import AlarmRule
    from .evaluation import RegistrationError
    from .measure import Roi
    from .pipeline import FusedFrame


def plot_registration_error(rows: list[RegistrationError], path: str | Path) -> Path:
    """Median and 95th-percentile error (thermal px) vs distance per method, as a PNG."""
    plt = pyplot()
    floor = 1e-3  # errors below it (exact depth quanta) are drawn on it: log axis
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for method in sorted({r.method for r in rows}):
        sel = [r for r in rows if r.method == method]
        d = [r.distance_m for r in sel]
        med = [max(r.median_px, floor) for r in sel]
        line = ax.plot(d, med, "o-", label=f"{method}: median")[0]
        ax.plot(
            d,
            [max(r.p95_px, floor) for r in sel],
            "--",
            color=line.get_color(),
            label=f"{method}: 95th percentile",
        )
    ax.set_ylim(floor / 2, None)
    ax.set_yscale("log")
    ax.set_xlabel("distance to the wall (m)")
    ax.set_ylabel("registration error (thermal pixels)")
    ax.set_title(
        "Depth -> thermal correspondence error vs ground truth\n"
        "(errors below 0.001 px drawn at 0.001)",
        fontsize=10,
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, path)


def plot_vox_curves(model: CompensationModel, table: SweepTable, out_dir: str | Path) -> list[Path]:
    """The paper's Fig. 13 (uncompensated readings vs VOx temperature per distance, with the
    model's curves) and Fig. 14 (compensated readings), one panel per target temperature.
    Points are means per 1 C of VOx. Returns the two PNG paths."""
    plt = pyplot()
    refs = np.unique(table["reference_temp_c"])
    compensated = apply_to_table(model, table).temp_c
    paths = []
    for name, values, title, with_curves in (
        ("fig13_uncompensated.png", table["measured_temp_c"], "uncompensated (Fig. 13)", True),
        ("fig14_compensated.png", compensated, f"compensated, {model.method} (Fig. 14)", False),
    ):
        fig, axes = plt.subplots(
            2,
            refs.size,
            figsize=(5.2 * refs.size, 6.0),
            squeeze=False,
            sharex="col",
            gridspec_kw={"height_ratios": [3, 2]},
        )
        bins = by_vox(values, table)  # means per 1 C of VOx
        for col, r in enumerate(refs):
            ax, low = axes[0, col], axes[1, col]
            dists = sorted(d for (rr, d) in bins if rr == r)
            nearest = bins[(float(r), dists[0])]
            for d, (color, marker) in zip(dists, distinct_styles(len(dists)), strict=True):
                x, y = np.array(list(bins[(float(r), d)].items())).T
                ax.plot(x, y, marker, ms=4, color=color, label=f"{d:g} m", ls="none")
                if with_curves:  # the model's prediction of the uncompensated reading
                    xs = np.linspace(x.min(), x.max(), 100)
                    ax.plot(xs, model.predict_measured(r, xs, d), "-", color=color, lw=1)
                # the distances told apart: each minus the nearest distance, VOx bin by bin
                both = [v for v in x if v in nearest]
                diff = [bins[(float(r), d)][v] - nearest[v] for v in both]
                low.plot(both, diff, marker + "-", ms=4, lw=0.8, color=color, label=f"{d:g} m")
            ax.axhline(r, color="k", lw=0.8, ls=":")
            ax.set_ylabel("reading (C)")
            ax.set_title(f"{r:g} C target, {title}", fontsize=10)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, ncol=2)
            low.axhline(0, color="k", lw=0.8, ls=":")
            low.set_xlabel("VOx (sensor) temperature (C)")
            low.set_ylabel(f"minus the {dists[0]:g} m reading (C)")
            low.grid(alpha=0.3)
        paths.append(save_figure(fig, Path(out_dir) / name))
    return paths


MIN_BOX_PX = 16
"""The smallest hotspot box drawn on an overlay (pixels a side): a far hotspot stays visible."""

NO_TEMPERATURE = (
    (Reason.INVALID_DEPTH, "no depth", (0.0, 0.55, 0.55), False),
    (Reason.OUTSIDE, "outside the thermal view", (0.75, 0.75, 0.75), False),
    (Reason.OCCLUDED, "hidden from the thermal camera", (0.1, 0.8, 0.1), True),
)
"""Why a depth pixel has no temperature, and how an overlay shows it: a tint (RGB 0-1), solid
or striped, over the scene. Teal, green and light grey lie outside the temperature palette
(inferno, as the viewer's: its green never leads its red by more than 0.015, and it has no
light grey), so no such pixel reads as a temperature."""
STRIPE_PX = 4
"""The width of the stripes over hidden pixels (depth pixels)."""


def overlay_rgb(frame: FusedFrame, range_c: tuple[float, float]) -> NDArray[np.float32]:
    """The overlay's image, (H, W, 3) RGB 0-1 on the depth grid: the temperature (inferno over
    ``range_c``, C) at 70 % over the depth camera's IR image (or a shaded depth map, near
    light), the pixels without a temperature shown by why (:data:`NO_TEMPERATURE`), the
    frame's isotherm bands in :data:`~thermodepth.isotherms.ISOTHERM_RGB`. Composited
    here, as matplotlib's alpha would, so that a figure draws one image."""
    if frame.ir is not None:
        grey = frame.ir.astype(np.float32) / 255.0
    else:  # near is light, far is dark
        z = frame.depth_m
        lo, hi = np.nanpercentile(z, [2, 98]) if np.isfinite(z).any() else (0.0, 1.0)
        grey = np.clip(np.nan_to_num((hi - z) / max(hi - lo, 1e-6), nan=0.0), 0.0, 1.0)
    rgb = np.repeat(grey[..., None], 3, axis=-1).astype(np.float32)
    reason = frame.reason_depth
    for why, _, tint, striped in NO_TEMPERATURE:
        v, u = np.nonzero(reason == why)
        if striped:  # every other diagonal band
            on = ((u + v) // STRIPE_PX) % 2 == 0
            v, u = v[on], u[on]
        rgb[v, u] = 0.3 * rgb[v, u] + 0.7 * np.asarray(tint, np.float32)
    t = frame.temp_depth_c
    seen = np.isfinite(t)
    colours = temperature_rgb(t[seen], range_c).astype(np.float32) / 255.0
    rgb[seen] = 0.3 * rgb[seen] + 0.7 * colours
    # isotherms: their band in one colour outside every palette (thermodepth.isotherms)
    for iso in frame.isotherms:
        rgb.reshape(-1, 3)[iso.pixels] = np.asarray(ISOTHERM_RGB, np.float32) / 255.0
    return rgb


MIN_OUTLINE_PX = 64
"""A depth-range ROI's pieces smaller than this (pixels) are not outlined: depth noise."""
ALARM_RGB = (1.0, 0.16, 0.16)
"""An ROI that a raised alarm rule watches is outlined in this red (RGB 0-1), thicker than
the others' white, and labelled with the rule's level (``plate: ALARM``, ``plate: WARNING``)."""


def roi_outlines(roi: Roi, depth_m: NDArray[np.floating]) -> list[NDArray[np.int32]]:
    """Where an ROI is on the depth image, as closed outlines, each an (N, 2) array of pixel
    vertices (u, v): a rectangle's corners (its last pixels inside), a polygon's vertices, a
    depth range's outer edges of its pieces in ``depth_m`` ((H, W), m) of at least
    :data:`MIN_OUTLINE_PX` pixels (none: an empty list); a line's two ends; an isotherm none
    (its band is drawn in the image, :func:`overlay_rgb`)."""
    from .measure import PolygonRoi, RectRoi

    if isinstance(roi, LineRoi):
        return [np.round(np.asarray([roi.start, roi.end])).astype(np.int32)]
    if isinstance(roi, IsothermRoi):
        return []

    if isinstance(roi, RectRoi):
        corners = [
            (roi.u0, roi.v0),
            (roi.u1 - 1, roi.v0),
            (roi.u1 - 1, roi.v1 - 1),
            (roi.u0, roi.v1 - 1),
        ]
        return [np.array(corners, np.int32)]
    if isinstance(roi, PolygonRoi):
        return [np.round(np.asarray(roi.vertices)).astype(np.int32)]
    mask = roi.mask(depth_m.shape, depth_m).astype(np.uint8)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    return [c[:, 0, :].astype(np.int32) for c in contours if cv2.contourArea(c) >= MIN_OUTLINE_PX]


def alarm_rois(rules: Iterable[AlarmRule], names: Collection[str]) -> dict[str, str]:
    """The ROIs that the rules named ``names`` watch, each with the highest level of those
    rules (``alarm`` or ``warning``): a rule's subject (``what``, unless it is the hotspot)
    and a delta rule's reference ROI (``relative_to``)."""
    out: dict[str, str] = {}
    for rule in rules:
        if rule.name in names:
            for roi in (rule.what, rule.relative_to):
                if roi and roi != "hotspot" and out.get(roi) != "alarm":
                    out[roi] = rule.level
    return out


def display_range_c(temp_c: NDArray[np.floating]) -> tuple[float, float]:
    """A colour scale for a run or a report, from one frame's temperatures (C): its 1st
    percentile to its maximum, widened to multiples of 5 C (15-80 C where there is none)."""
    t = np.asarray(temp_c)
    if not np.isfinite(t).any():
        return 15.0, 80.0
    lo = 5.0 * np.floor(float(np.nanpercentile(t, 1)) / 5.0)
    hi = 5.0 * np.ceil(float(np.nanmax(t)) / 5.0)
    return lo, max(hi, lo + 5.0)


def plot_overlay(
    frame: FusedFrame,
    path: str | Path,
    title: str | None = None,
    vmin_c: float | None = None,
    vmax_c: float | None = None,
    rois: Sequence[Roi] = (),
    marked: Mapping[str, str] | None = None,
) -> Path:
    """The fused temperature (colour map) over the depth camera's IR image (or a shaded
    depth map), the pixels without a temperature tinted by why (legend), hotspot boxes
    (at least :data:`MIN_BOX_PX` a side) labelled in C, metres and cm^2 where the label does
    not cover the box, and a colour bar. ``vmin_c``/``vmax_c``: the colour scale (C); give
    them for every image of a run or a report (:func:`display_range_c`), so that a colour
    means one temperature throughout; None: this frame's own (:func:`display_range_c`).
    ``rois``: outlined in white with their names (a depth range only when marked); those
    in ``marked`` (name: level of the raised rule that watches it, :func:`alarm_rois`) in
    :data:`ALARM_RGB`, thicker, labelled ``NAME: LEVEL``."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.patches import Patch, Polygon, Rectangle

    from .measure import DepthRangeRoi, hotspot_box_on_depth

    plt = pyplot()
    cal = frame.calibration
    h, w = cal.depth.shape
    fig, ax = plt.subplots(figsize=(w / 100 + 1.6, h / 100 + 0.9), dpi=100)
    t = frame.temp_depth_c
    lo_c, hi_c = vmin_c, vmax_c
    if lo_c is None or hi_c is None:  # a percentile of the whole image: only when needed
        auto_lo, auto_hi = display_range_c(t)
        lo_c = auto_lo if lo_c is None else lo_c
        hi_c = auto_hi if hi_c is None else hi_c
    # one image drawn: one resampling instead of a layer's each (half the time at 1280x720)
    rgb = overlay_rgb(frame, (lo_c, hi_c))
    ax.imshow(rgb, interpolation="nearest")
    im = ScalarMappable(Normalize(lo_c, hi_c), "inferno")
    marked = marked or {}
    for roi in rois:
        alarm = roi.name in marked
        if not alarm and isinstance(roi, DepthRangeRoi):
            continue  # a depth range: outlined only when its alarm is raised
        color = ALARM_RGB if alarm else "white"
        outlines = roi_outlines(roi, frame.depth_m)
        for pts in outlines:
            ax.add_patch(Polygon(pts, closed=True, fill=False, ec=color, lw=2.5 if alarm else 1))
        if outlines:
            u, v = min((tuple(p) for pts in outlines for p in pts), key=lambda p: (p[1], p[0]))
            text = f"{roi.name}: {marked[roi.name].upper()}" if alarm else roi.name
            back = (
                {"facecolor": color, "alpha": 0.8}
                if alarm
                else {"facecolor": "black", "alpha": 0.5}
            )
            ax.text(u + 2, v + 2, text, va="top", color="white", fontsize=8 if alarm else 7,
                    fontweight="bold" if alarm else None,
                    bbox={**back, "pad": 1, "lw": 0})  # fmt: skip
    for hs in frame.hotspots:
        box = hotspot_box_on_depth(
            hs, frame.z_thermal_m, cal.thermal, cal.depth, cal.thermal_from_depth
        )
        if box is None:
            continue
        u0, v0, u1, v1 = _at_least(box, MIN_BOX_PX, w, h)
        color = "cyan" if hs.resolvable else "yellow"
        ax.add_patch(Rectangle((u0, v0), u1 - u0, v1 - v0, fill=False, ec=color, lw=1.5))
        label = f"{hs.max_c:.1f} C  {hs.distance_m:.2f} m  {hs.area_m2 * 1e4:.1f} cm$^2$" + (
            "" if hs.resolvable else "  (too small: reads low)"
        )
        above = v0 - 4 > 24  # room above the box: the label never covers what it names
        ax.text(
            u0,
            v0 - 4 if above else v1 + 4,
            label,
            color=color,
            fontsize=9,
            va="bottom" if above else "top",
            bbox={"facecolor": "black", "alpha": 0.5, "pad": 1, "lw": 0},
        )
    fig.colorbar(im, ax=ax, fraction=0.03, pad=0.01, label="temperature (C)")
    handles = [
        Patch(facecolor=(0.6, 0.6, 0.6), edgecolor=tint, hatch="////", label=text)
        if striped
        else Patch(facecolor=tint, label=text)
        for _, text, tint, striped in NO_TEMPERATURE
    ]
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.01), ncol=3,
              fontsize=8, frameon=False, title="no temperature:", title_fontsize=8)  # fmt: skip
    ax.set_title(title or f"frame {frame.index}: VOx {frame.vox_label}", fontsize=10)
    ax.set_axis_off()
    return save_figure(fig, path)


def _at_least(
    box: tuple[int, int, int, int], side: int, w: int, h: int
) -> tuple[float, float, float, float]:
    """A box (u0, v0, u1, v1) grown about its centre to ``side`` pixels where smaller."""
    u0, v0, u1, v1 = box
    cu, cv = (u0 + u1) / 2, (v0 + v1) / 2
    half_u, half_v = max((u1 - u0) / 2, side / 2), max((v1 - v0) / 2, side / 2)
    return (
        max(cu - half_u, 0),
        max(cv - half_v, 0),
        min(cu + half_u, w - 1),
        min(cv + half_v, h - 1),
    )


def plot_target(
    temp_c: np.ndarray, target: np.ndarray | None, title: str, path: str | Path
) -> Path:
    """A thermal frame's apparent temperature (C, colour map from its coldest to hottest) with the
    sweep target's outline in cyan (``target``: (h, w) mask, None: not found), so that a user
    can confirm what ``collect-sweep`` reads."""
    plt = pyplot()
    h, w = temp_c.shape
    fig, ax = plt.subplots(figsize=(w / 40 + 1.4, h / 40 + 0.6), dpi=100)
    finite = np.isfinite(temp_c)
    lo, hi = (np.nanmin(temp_c), np.nanmax(temp_c)) if finite.any() else (0.0, 1.0)
    im = ax.imshow(np.ma.masked_invalid(temp_c), cmap="inferno", vmin=lo, vmax=max(hi, lo + 0.1))
    if target is not None and target.any():
        ax.contour(target.astype(float), levels=[0.5], colors="cyan", linewidths=1.5)
    fig.colorbar(im, ax=ax, fraction=0.04, pad=0.02, label="apparent temperature (C)")
    ax.set_title(title, fontsize=8, wrap=True)
    ax.set_xlabel("u (thermal px)")
    ax.set_ylabel("v (thermal px)")
    return save_figure(fig, path)
