"""The surfaces a depth image sees: depth smoothed on each surface, the local surface normal
and each depth pixel's footprint on the surface (m^2), for lengths and areas in real units
(line profiles: :mod:`thermodepth.lines`; isotherm areas: :mod:`thermodepth.isotherms`).

A stereo depth camera's depth is noisy pixel to pixel (a D435: sigma_z = z^2 * 0.08 /
(fx * 0.05 m), 1.5 cm at 2.5 m), and a length summed pixel by pixel, or a normal taken from
neighbouring pixels, would take that noise for relief. So both are taken from depth averaged
over a window of :data:`SMOOTH_PX` pixels a side, of the pixels of the same surface only: a
pixel whose window mean departs from its own depth by more than :data:`SAME_SURFACE` of it
(a depth edge inside the window) keeps its own depth. Within half a window of a depth edge,
normals are taken over a shorter baseline or not at all (see :func:`surface_normals`).

A depth pixel's footprint on a surface of unit normal n is, for a pinhole camera
(undistorted normalised ray r = (x, y, 1), focal lengths fx, fy in pixels, depth Z):

    A = Z^2 / (fx fy |n . r|)  =  (Z / fx)(Z / fy) cos(alpha) / cos(theta)

theta: the angle between the normal and the viewing ray; alpha: the ray's angle off the
optical axis. (A surface facing the camera squarely, n = -z, has A = (Z/fx)(Z/fy) at every
pixel: its image is the surface scaled by Z; the familiar (Z/fx)(Z/fy)/cos(theta) holds on
the optical axis only, and would overstate a corner pixel of a D435 by a third.)
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from .camera import Intrinsics, pixel_rays

FloatArray = NDArray[np.floating]

SMOOTH_PX = 15
"""The side of the window (depth pixels) over which depth is averaged before lengths and
normals are taken: the noise of a depth step falls 15-fold, and a plane stays a plane."""
SAME_SURFACE = 0.03
"""A pixel whose window mean departs from its own depth by more than this share of it has a
depth edge in its window: it keeps its own depth (3 % of Z: 5 sigma of a D435 at 2.5 m)."""
NORMAL_STEP_PX = 7
"""The half baseline (pixels) of the differences that give a normal from smoothed depth."""


def box(rows: slice, cols: slice, shape: tuple[int, int], margin: int) -> tuple[slice, slice]:
    """A box of an image of ``shape`` (H, W) grown by ``margin`` pixels each way, clipped."""
    return (
        slice(max(rows.start - margin, 0), min(rows.stop + margin, shape[0])),
        slice(max(cols.start - margin, 0), min(cols.stop + margin, shape[1])),
    )


def smoothed_depth(z_m: FloatArray, window_px: int = SMOOTH_PX) -> NDArray[np.float32]:
    """Depth (H, W) m averaged over ``window_px`` x ``window_px`` of its valid pixels, each
    pixel's own depth kept where its window holds a depth edge (module docstring); NaN where
    ``z_m`` is NaN."""
    z = np.asarray(z_m, np.float32)
    valid = np.isfinite(z)
    filled = np.where(valid, z, np.float32(0))
    size = (window_px, window_px)
    total = cv2.boxFilter(filled, -1, size, normalize=False, borderType=cv2.BORDER_CONSTANT)
    count = cv2.boxFilter(
        valid.astype(np.float32), -1, size, normalize=False, borderType=cv2.BORDER_CONSTANT
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = total / count
        edge = np.abs(mean - z) > np.float32(SAME_SURFACE) * z
    return np.where(valid & ~edge, mean, z).astype(np.float32)


def surface_points(
    z_m: FloatArray, depth: Intrinsics, rows: slice, cols: slice
) -> NDArray[np.float64]:
    """3D points (h, w, 3) m in the depth camera's frame of the pixels of a box (rows,
    cols) of a depth map ``z_m`` of that box (h, w): each pixel's ray times its depth."""
    x, y = pixel_rays(depth)
    z = np.asarray(z_m, np.float64)
    return np.stack([x[rows, cols] * z, y[rows, cols] * z, z], axis=-1)


def surface_normals(
    points: NDArray[np.float64],
    v: NDArray[np.intp],
    u: NDArray[np.intp],
    step_px: int = NORMAL_STEP_PX,
) -> NDArray[np.float64]:
    """Unit normals (N, 3), facing the camera, at the pixels (v, u) (N,) of a grid of
    surface points (h, w, 3) (of smoothed depth, :func:`smoothed_depth`): the cross product
    of the differences ``step_px`` pixels each way along the row and the column; where a
    point that far is missing (NaN, or off the grid), one side's difference; NaN where
    neither side has one."""
    h, w, _ = points.shape
    here = points[v, u]

    def at(vv: NDArray[np.intp], uu: NDArray[np.intp]) -> NDArray[np.float64]:
        inside = (vv >= 0) & (vv < h) & (uu >= 0) & (uu < w)
        out = np.full((len(vv), 3), np.nan)
        out[inside] = points[vv[inside], uu[inside]]
        return out

    def difference(ahead: NDArray[np.float64], behind: NDArray[np.float64]) -> NDArray[np.float64]:
        both = ahead - behind
        one = np.where(np.isfinite(ahead), ahead - here, here - behind)
        return np.where(np.isfinite(both), both, one)

    k = step_px
    du = difference(at(v, u + k), at(v, u - k))
    dv = difference(at(v + k, u), at(v - k, u))
    n = np.cross(du, dv)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / np.linalg.norm(n, axis=1, keepdims=True)
    # face the camera: the normal points back along the ray (n . p < 0)
    flip = np.einsum("ij,ij->i", n, here) > 0
    return np.where(flip[:, None], -n, n)


def footprint_m2(
    z_m: FloatArray, normals: FloatArray, ray_x: FloatArray, ray_y: FloatArray, fx: float, fy: float
) -> FloatArray:
    """Each depth pixel's footprint on its surface (m^2): Z^2 / (fx fy |n . (x, y, 1)|)
    (module docstring). z_m, ray_x, ray_y: (N,) the pixels' depths and undistorted
    normalised rays; normals: (N, 3) unit; fx, fy: focal lengths (pixels). A grazing view
    (|n . r| below 0.1, theta beyond ~84 deg) is capped there: its footprint is no better
    than a guess."""
    dot = np.abs(normals[:, 0] * ray_x + normals[:, 1] * ray_y + normals[:, 2])
    return np.asarray(z_m, np.float64) ** 2 / (fx * fy * np.maximum(dot, 0.1))
