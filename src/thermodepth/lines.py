"""Line ROIs: the temperature along a line of the depth image against its length in metres
on the surface it crosses, its maximum and where that is.

A line ``[[u0, v0], [u1, v1]]`` (depth-image pixels, as a rect ROI's) is walked pixel by
pixel (one sample per pixel of its longer side, rounded to the nearest pixel). Each pixel
with a depth is a 3D point: its ray times its depth, the depth averaged over the surface
around it (:func:`~thermodepth.surface.smoothed_depth`, so that the depth camera's noise is
not taken for relief). The position of a pixel along the line is the cumulative 3D distance
between successive points, from the first pixel with a depth (0 m); the line's length is
that of its last such pixel.

Gaps: a pixel without a depth has no position (NaN) and no temperature; the distance across
a gap is the straight 3D chord between the points on either side of it. A pixel with a depth
but no temperature (outside the thermal view, hidden from it) has a position and a NaN
temperature. A line that crosses from one surface to another (a busbar's edge, the wall
behind) measures the step between them as part of its length: draw it on the surface.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .camera import Intrinsics, pixel_rays
from .surface import SMOOTH_PX, box, smoothed_depth

FloatArray = NDArray[np.floating]


@dataclass(frozen=True)
class LineRoi:
    """A line from (u0, v0) to (u1, v1) of the depth image (pixels, both ends on it)."""

    name: str
    start: tuple[float, float]
    end: tuple[float, float]

    def pixels(self, shape: tuple[int, int]) -> NDArray[np.intp]:
        """The line's pixels (N, 2) as (u, v), in order from its start, inside an image of
        ``shape`` (H, W): one per pixel of the longer side, each rounded."""
        (u0, v0), (u1, v1) = self.start, self.end
        n = int(np.ceil(max(abs(u1 - u0), abs(v1 - v0)))) + 1
        u = np.rint(np.linspace(u0, u1, n)).astype(np.intp)
        v = np.rint(np.linspace(v0, v1, n)).astype(np.intp)
        inside = (u >= 0) & (u < shape[1]) & (v >= 0) & (v < shape[0])
        uv = np.stack([u[inside], v[inside]], axis=-1)
        keep = np.ones(len(uv), bool)
        keep[1:] = (np.diff(uv, axis=0) != 0).any(axis=1)  # a pixel once
        return uv[keep]

    def mask(self, shape: tuple[int, int], depth_m: FloatArray | None = None) -> NDArray[np.bool_]:
        m = np.zeros(shape, dtype=bool)
        uv = self.pixels(shape)
        m[uv[:, 1], uv[:, 0]] = True
        return m


@dataclass(frozen=True)
class LineProfile:
    """A line's profile in one frame (module docstring).

    length_m: along the surface, first to last pixel with a depth (NaN: none has one);
    max_c: the hottest temperature on it (C, NaN: none), at max_at_m along it and pixel
    max_px (u, v); n: pixels with a temperature; gap_px: pixels without a depth or a
    temperature. distance_m, temp_c (N,): each pixel's position along the line (NaN: no
    depth) and temperature (NaN: none); pixels (N, 2): its (u, v).
    """

    name: str
    length_m: float
    max_c: float
    max_at_m: float
    max_px: tuple[int, int] | None
    n: int
    gap_px: int
    distance_m: NDArray[np.float64] = field(repr=False, compare=False)
    temp_c: NDArray[np.float32] = field(repr=False, compare=False)
    pixels: NDArray[np.intp] = field(repr=False, compare=False)

    def as_dict(self, profile: bool = True) -> dict[str, Any]:
        """Plain data (JSON): the figures and, with ``profile``, the profile (distance in
        mm steps, temperatures to 0.01 C; None: no value)."""
        d: dict[str, Any] = {
            "name": self.name,
            "length_m": round(self.length_m, 4),
            "max_c": round(self.max_c, 3),
            "max_at_m": round(self.max_at_m, 4),
            "max_px": None if self.max_px is None else list(self.max_px),
            "n": self.n,
            "gap_px": self.gap_px,
        }
        if profile:
            d["distance_m"] = np.round(self.distance_m, 4).tolist()
            d["temp_c"] = np.round(self.temp_c.astype(np.float64), 2).tolist()
        return d

    def stats(self) -> tuple[int, float, float, float, float]:
        """n, mean, max, min and SD of its temperatures (NaN when n = 0)."""
        t = self.temp_c[np.isfinite(self.temp_c)].astype(np.float64)
        if t.size == 0:
            nan = float("nan")
            return 0, nan, nan, nan, nan
        return int(t.size), float(t.mean()), float(t.max()), float(t.min()), float(t.std())


def line_profile(
    line: LineRoi, z_m: FloatArray, temp_c: FloatArray, depth: Intrinsics
) -> LineProfile:
    """The profile of ``line`` (module docstring) on a frame's depth grid: z_m (H, W) depth
    Z in metres (NaN: none), temp_c (H, W) temperatures (C, NaN: none), depth: the depth
    camera's intrinsics. Only the line's box (and a smoothing window round it) is read."""
    shape = z_m.shape
    uv = line.pixels(shape)
    u, v = uv[:, 0], uv[:, 1]
    nan = float("nan")
    if len(uv) == 0:
        empty = np.zeros(0)
        return LineProfile(line.name, nan, nan, nan, None, 0, 0, empty, empty.astype(np.float32),
                           uv)  # fmt: skip
    rows, cols = box(slice(v.min(), v.max() + 1), slice(u.min(), u.max() + 1), shape, SMOOTH_PX)
    z = smoothed_depth(z_m[rows, cols])[v - rows.start, u - cols.start].astype(np.float64)
    x, y = pixel_rays(depth)
    pts = np.stack([x[v, u] * z, y[v, u] * z, z], axis=-1)
    has = np.isfinite(z)
    steps = np.linalg.norm(np.diff(pts[has], axis=0), axis=1)  # chords across the gaps
    distance = np.full(len(uv), np.nan)
    distance[has] = np.concatenate([[0.0], np.cumsum(steps)]) if has.any() else []
    temp = np.asarray(temp_c[v, u], np.float32)
    temp = np.where(has, temp, np.float32(np.nan))
    seen = np.isfinite(temp)
    if seen.any():
        i = int(np.nanargmax(temp))
        max_c, max_at, max_px = float(temp[i]), float(distance[i]), (int(u[i]), int(v[i]))
    else:
        max_c, max_at, max_px = nan, nan, None
    length = float(distance[has][-1]) if has.any() else nan
    return LineProfile(
        line.name,
        length,
        max_c,
        max_at,
        max_px,
        int(seen.sum()),
        int((~seen).sum()),
        distance,
        temp,
        uv,
    )
