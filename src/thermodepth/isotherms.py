"""Isotherms: the pixels of the fused image at or above a temperature (optionally inside an
ROI), drawn as a band of one colour (:data:`ISOTHERM_RGB`, outside every palette's colours),
and their area in cm^2 on the surfaces they lie on.

The area is the sum over those depth pixels of each one's footprint on its surface
(:func:`~thermodepth.surface.footprint_m2`: Z^2 / (fx fy |n . r|), n the surface normal from
the smoothed depth's gradients, r the pixel's ray), so it is the same whatever the distance
and the tilt. Limits: the band is the thermal image's (its blur and pixels, sampled onto the
depth grid; ``registration.interpolation: bilinear`` puts its edge between thermal pixels,
nearest at their borders), so a threshold near the hot part's own temperature shrinks it, and
a part smaller than a few thermal pixels reads too small or not at all; within half a
smoothing window (:data:`~thermodepth.surface.SMOOTH_PX`) of a depth edge the normal is
taken one-sided, and where no normal can be taken, the mean normal of the band's other
pixels stands in (none: facing the camera); a grazing view (beyond ~84 deg) is capped.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .camera import Intrinsics, pixel_rays
from .surface import (
    NORMAL_STEP_PX,
    SMOOTH_PX,
    box,
    footprint_m2,
    smoothed_depth,
    surface_normals,
    surface_points,
)

FloatArray = NDArray[np.floating]

ISOTHERM_RGB = (255, 0, 255)
"""The isotherm band's colour (magenta, RGB 0-255): at least 139 RGB units from every colour
of every palette of :mod:`thermodepth.palettes` (the overlay's temperatures among them) and
apart from the overlay's tints of pixels without a temperature."""


@dataclass(frozen=True)
class IsothermRoi:
    """The pixels at or above ``above_c`` (C), inside the ROI named ``within`` (None: the
    whole image)."""

    name: str
    above_c: float
    within: str | None = None

    def mask(self, shape: tuple[int, int], depth_m: FloatArray | None = None) -> NDArray[np.bool_]:
        raise ValueError(f"ROI {self.name!r}: an isotherm's pixels are the frame's (its band)")


@dataclass(frozen=True)
class IsothermArea:
    """An isotherm in one frame: its area on the surfaces (cm^2), how many depth pixels it
    holds (n), their temperatures' mean, max, min and SD (C, NaN when n = 0), and which
    pixels (flat indices of the depth grid, raster order)."""

    name: str
    above_c: float
    area_cm2: float
    n: int
    mean_c: float
    max_c: float
    min_c: float
    sd_c: float
    pixels: NDArray[np.intp] = field(repr=False, compare=False)

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "above_c": self.above_c,
            "area_cm2": round(self.area_cm2, 3),
            "n": self.n,
            "max_c": round(self.max_c, 3),
            "mean_c": round(self.mean_c, 3),
        }


def isotherm_area(
    iso: IsothermRoi,
    temp_c: FloatArray,
    z_m: FloatArray,
    depth: Intrinsics,
    within: NDArray[np.bool_] | None = None,
) -> IsothermArea:
    """The isotherm ``iso`` of a frame's depth grid (module docstring): temp_c (H, W)
    temperatures (C, NaN: none), z_m (H, W) depth Z (m, NaN: none), depth: the depth
    camera's intrinsics, within: (H, W) the ROI it is confined to (None: all). Only the
    band's box (and a window round it) is read for its geometry."""
    shape = temp_c.shape
    with np.errstate(invalid="ignore"):
        hot = temp_c >= iso.above_c
    if within is not None:
        hot &= within
    flat = np.flatnonzero(hot)
    nan = float("nan")
    if flat.size == 0:
        return IsothermArea(iso.name, iso.above_c, 0.0, 0, nan, nan, nan, nan, flat)
    v, u = np.divmod(flat, shape[1])
    margin = SMOOTH_PX + NORMAL_STEP_PX
    rows, cols = box(slice(v.min(), v.max() + 1), slice(u.min(), u.max() + 1), shape, margin)
    zs = smoothed_depth(z_m[rows, cols])
    vi, ui = v - rows.start, u - cols.start
    n = surface_normals(surface_points(zs, depth, rows, cols), vi, ui)
    z = zs[vi, ui].astype(np.float64)
    missing = ~np.isfinite(n).all(axis=1)
    if missing.any():
        known = n[~missing]
        stand_in = known.mean(axis=0) if len(known) else np.array([0.0, 0.0, -1.0])
        n[missing] = stand_in / np.linalg.norm(stand_in)
    x, y = pixel_rays(depth)
    area = footprint_m2(z, n, x[v, u], y[v, u], depth.fx, depth.fy)
    t = temp_c[v, u].astype(np.float64)
    return IsothermArea(
        iso.name,
        iso.above_c,
        float(np.nansum(area)) * 1e4,
        int(flat.size),
        float(t.mean()),
        float(t.max()),
        float(t.min()),
        float(t.std()),
        flat,
    )
