"""Ray casting of rect scenes for a pinhole camera with distortion, and of arbitrary rays
(numba kernels of :mod:`.kernels`).

A camera's rays are given as a grid of undistorted normalised coordinates (x, y): the ray
through a (sub)pixel is d = (x, y, 1) in the camera frame, so the hit parameter t is the depth
Z along the optical axis and the range is t |d|. Each rect is tested only on the rows and
columns of the grid whose rays reach into the bounds of its view (of the part of it in front
of the camera); the nearest hit wins (z-buffer).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from ..camera import Intrinsics, RigidTransform, corner_rays, pixel_rays
from . import kernels
from .scene import Scene

FloatArray = NDArray[np.float64]


def rect_params(scene: Scene, camera_from_world: RigidTransform) -> FloatArray:
    """Kernel parameters (R, 14) of the scene's rects expressed in the camera frame
    (:mod:`.kernels` has the layout)."""
    out = np.empty((len(scene.rects), 14))
    rot, t = camera_from_world.rotation, camera_from_world.translation_m
    normals = scene.geometry.normal
    # one rect at a time: products of whole arrays would round a last bit differently
    for i, r in enumerate(scene.rects):
        c = r.center_m @ rot.T + t
        n, u, v = rot @ normals[i], rot @ r.axis_u, rot @ r.axis_v
        out[i] = [*n, n @ c, *u, u @ c, *v, v @ c, r.half_u_m, r.half_v_m]
    return out


_NEAREST_M = 1e-6  # a rect that passes nearer the camera centre is tested on every ray
_MARGIN = 1e-9  # relative widening of a rect's view bounds, far beyond rounding


def _view_bounds(
    scene: Scene, camera_from_world: RigidTransform, reach: float
) -> tuple[FloatArray, NDArray[np.bool_], NDArray[np.bool_]]:
    """Where each rect can be seen by rays (x, y, 1) with |x|, |y| <= ``reach``: bounds
    (R, 4) x0, x1, y0, y1 in undistorted normalised coordinates of the part of it in front of
    the camera, whether any is (R,), and whether it passes so near the camera centre that
    every ray must be tested (R,).

    The part in front: the rect clipped at a depth eps too small for such a ray to meet it
    there (eps = d / (4 sqrt(1 + 2 reach^2)), d the rect's distance from the camera centre:
    a point that near lies nearer than d). A pinhole's image of that convex polygon is the
    convex hull of its vertices', so their bounds (widened by far more than rounding) hold
    every ray that meets the rect."""
    g = scene.geometry
    eye = camera_from_world.inverse().translation_m
    d = eye - g.center_m  # the closest point of each rect to the eye, in its (s, q)
    s = np.clip(np.einsum("ij,ij->i", d, g.axis_u), -g.half_m[:, 0], g.half_m[:, 0])
    q = np.clip(np.einsum("ij,ij->i", d, g.axis_v), -g.half_m[:, 1], g.half_m[:, 1])
    nearest = np.linalg.norm(d - s[:, None] * g.axis_u - q[:, None] * g.axis_v, axis=1)
    eps = nearest / (4.0 * np.sqrt(1.0 + 2.0 * reach**2))
    corners = camera_from_world.apply(scene.corners_m)  # (R, 4, 3)
    a, b = corners, np.roll(corners, -1, axis=1)  # each edge a -> b
    za, zb = a[..., 2] - eps[:, None], b[..., 2] - eps[:, None]
    crosses = za * zb < 0
    f = np.where(crosses, -za / np.where(crosses, zb - za, 1.0), 0.0)
    pts = np.concatenate([a, a + f[..., None] * (b - a)], axis=1)  # (R, 8, 3)
    kept = np.concatenate([za >= 0, crosses], axis=1)
    z = np.where(kept, pts[..., 2], 1.0)
    bounds = np.empty((len(g.center_m), 4))
    # no warnings for a rect with nothing in front, or through the camera centre: those are
    # marked as such
    with np.errstate(divide="ignore", invalid="ignore"):
        for k, axis in ((0, 0), (2, 1)):
            x = pts[..., axis] / z
            lo = np.where(kept, x, np.inf).min(axis=1)
            hi = np.where(kept, x, -np.inf).max(axis=1)
            bounds[:, k] = lo - _MARGIN * (1.0 + np.abs(lo))
            bounds[:, k + 1] = hi + _MARGIN * (1.0 + np.abs(hi))
    return bounds, np.asarray(kept.any(axis=1)), np.asarray(nearest <= _NEAREST_M)


@lru_cache(maxsize=16)
def _grid_extents(intr: Intrinsics, ss: int) -> tuple[FloatArray, ...]:
    """A camera's (sub)pixel rays (:func:`~thermodepth.camera.pixel_rays`): the least and
    greatest y of each row, x of each column, and the greatest |x| or |y| of all."""
    xs, ys = pixel_rays(intr, ss)
    reach = np.array([max(np.abs(xs).max(), np.abs(ys).max())])
    return ys.min(axis=1), ys.max(axis=1), xs.min(axis=0), xs.max(axis=0), reach


def _bboxes(
    scene: Scene, camera_from_world: RigidTransform, intr: Intrinsics, ss: int
) -> NDArray[np.int64]:
    """Inclusive (row0, row1, col0, col1) of each rect in the supersampled grid, (R, 4): the
    rows and columns whose rays reach into its view bounds (:func:`_view_bounds`), so every
    ray that meets it is inside; nothing where no part of it is in front of the camera, the
    whole grid where it passes by the camera centre."""
    row_lo, row_hi, col_lo, col_hi, reach = _grid_extents(intr, ss)
    bounds, front, near = _view_bounds(scene, camera_from_world, float(reach[0]))
    rows = (row_hi >= bounds[:, 2, None]) & (row_lo <= bounds[:, 3, None])  # (R, H)
    cols = (col_hi >= bounds[:, 0, None]) & (col_lo <= bounds[:, 1, None])  # (R, W)
    h, w = rows.shape[1], cols.shape[1]
    out = np.stack(
        [
            np.argmax(rows, axis=1),
            h - 1 - np.argmax(rows[:, ::-1], axis=1),
            np.argmax(cols, axis=1),
            w - 1 - np.argmax(cols[:, ::-1], axis=1),
        ],
        axis=1,
    )
    out[~(front & rows.any(axis=1) & cols.any(axis=1))] = [1, 0, 1, 0]  # empty
    out[near] = [0, h - 1, 0, w - 1]
    return out


@dataclass(frozen=True, eq=False)
class Hits:
    """What each ray of a grid hits: z (depth along the axis, m; inf = nothing), the rect
    index (-1 = nothing), the local (s, q) coordinates on it, and the range (m)."""

    z_m: FloatArray
    rect: NDArray[np.int64]
    s_m: FloatArray
    q_m: FloatArray
    range_m: FloatArray


def cast(
    scene: Scene,
    camera_from_world: RigidTransform,
    intr: Intrinsics,
    supersample: int = 1,
) -> Hits:
    """Cast one ray per (sub)pixel of a camera into the scene; arrays (H*ss, W*ss)."""
    xs, ys = pixel_rays(intr, supersample)
    z, s, q, rng = (np.empty(xs.shape) for _ in range(4))
    ids = np.empty(xs.shape, dtype=np.int64)
    kernels.cast_grid(
        xs, ys, *grid_params(scene, camera_from_world, intr, supersample), z, ids, s, q, rng
    )
    return Hits(z, ids, s, q, rng)


def grid_params(
    scene: Scene, camera_from_world: RigidTransform, intr: Intrinsics, supersample: int
) -> tuple[FloatArray, NDArray[np.int64]]:
    """What a cast of a camera's (sub)pixel grid takes: the rects' parameters in the camera
    frame (:func:`rect_params`) and their bounding boxes in the grid (R, 4)."""
    return rect_params(scene, camera_from_world), _bboxes(
        scene, camera_from_world, intr, supersample
    )


@dataclass(frozen=True, eq=False)
class RayHits:
    """What each of N rays hits: t, how far along the ray (in units of its direction's
    length: metres for unit directions; inf = nothing), the rect index (-1 = nothing) and
    the local (s, q) coordinates on it (m; NaN = nothing); arrays (N,)."""

    t: FloatArray
    rect: NDArray[np.int64]
    s_m: FloatArray
    q_m: FloatArray


def cast_rays(
    scene: Scene,
    origins_m: FloatArray,
    directions: FloatArray,
    frame_from_world: RigidTransform | None = None,
    skip: NDArray[np.int64] | None = None,
) -> RayHits:
    """Cast arbitrary rays o + t d (origins (N, 3) m, directions (N, 3)) into the scene and
    find the nearest rect each meets at t > 0.

    The rays are given in the frame ``frame_from_world`` maps the world to (None: the world
    frame); ``skip`` (N,): a rect index each ray ignores (-1: none), the surface a ray leaves
    (a reflection). Every rect is tested (no culling): for a few rays, not an image grid
    (:func:`cast`).
    """
    world = frame_from_world or RigidTransform.identity("world", "world")
    prims = rect_params(scene, world)
    o = np.ascontiguousarray(origins_m, dtype=np.float64).reshape(-1, 3)
    d = np.ascontiguousarray(directions, dtype=np.float64).reshape(-1, 3)
    n = o.shape[0]
    skip = np.full(n, -1, np.int64) if skip is None else np.ascontiguousarray(skip, np.int64)
    t, s, q = np.empty(n), np.empty(n), np.empty(n)
    ids = np.empty(n, dtype=np.int64)
    kernels.cast_rays(o, d, skip, prims, t, ids, s, q)
    return RayHits(t, ids, s, q)


def blocked(
    scene: Scene,
    camera_from_world: RigidTransform,
    points_cam_m: FloatArray,
    tol: float = 1e-6,
    in_image: Intrinsics | None = None,
) -> NDArray[np.bool_]:
    """True where the line of sight from the camera centre to each point (N, 3, camera
    frame) is blocked by a rect before reaching it (relative tolerance ``tol``).

    ``in_image``: the points all lie inside this camera's image, so only the rects that
    reach into it are tested (a line of sight inside the image meets no other).
    """
    prims = rect_params(scene, camera_from_world)
    if in_image is not None:  # the image's extent: its pixel corners' rays, and 2 px more
        xc, yc = corner_rays(in_image)
        x0, x1 = xc.min() - 2.0 / in_image.fx, xc.max() + 2.0 / in_image.fx
        y0, y1 = yc.min() - 2.0 / in_image.fy, yc.max() + 2.0 / in_image.fy
        reach = max(abs(x0), abs(x1), abs(y0), abs(y1))
        bounds, front, near = _view_bounds(scene, camera_from_world, reach)
        seen = (bounds[:, 1] >= x0) & (bounds[:, 0] <= x1)
        seen &= (bounds[:, 3] >= y0) & (bounds[:, 2] <= y1)
        prims = np.ascontiguousarray(prims[near | (front & seen)])
    pts = np.ascontiguousarray(points_cam_m, dtype=np.float64).reshape(-1, 3)
    out = np.empty(pts.shape[0], dtype=np.bool_)
    kernels.blocked(pts, prims, tol, out)
    return out.reshape(np.shape(points_cam_m)[:-1])
