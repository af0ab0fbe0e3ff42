"""Ray casting of rect scenes for a pinhole camera with distortion (numba kernels).

A camera's rays are given as a grid of undistorted normalised coordinates (x, y): the ray
through a (sub)pixel is d = (x, y, 1) in the camera frame, so the hit parameter t is the depth
Z along the optical axis and the range is t |d|. Each rect is tested only inside the
(sub)pixel bounding box of its projected outline; the nearest hit wins (z-buffer).
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import NDArray

from ..camera import Intrinsics, RigidTransform, pixel_rays
from .scene import Rect, Scene

FloatArray = NDArray[np.float64]

# per-rect row: n (3), n.c, u (3), u.c, v (3), v.c, half_u, half_v  (camera frame)
_N_PARAMS = 14


@numba.njit(parallel=True, cache=True)
def _cast_grid(xs, ys, prims, bbox, z_out, id_out, s_out, q_out, r_out):  # pragma: no cover
    h, w = xs.shape
    for r in numba.prange(h):
        for c in range(w):
            z_out[r, c] = np.inf
            id_out[r, c] = -1
            s_out[r, c] = np.nan
            q_out[r, c] = np.nan
        for p in range(prims.shape[0]):
            if r < bbox[p, 0] or r > bbox[p, 1]:
                continue
            n0, n1, n2, nc = prims[p, 0], prims[p, 1], prims[p, 2], prims[p, 3]
            u0, u1, u2, uc = prims[p, 4], prims[p, 5], prims[p, 6], prims[p, 7]
            v0, v1, v2, vc = prims[p, 8], prims[p, 9], prims[p, 10], prims[p, 11]
            hu, hv = prims[p, 12], prims[p, 13]
            for c in range(bbox[p, 2], bbox[p, 3] + 1):
                x = xs[r, c]
                y = ys[r, c]
                nd = n0 * x + n1 * y + n2
                if nd == 0.0:
                    continue
                t = nc / nd
                if t <= 0.0 or t >= z_out[r, c]:
                    continue
                s = t * (u0 * x + u1 * y + u2) - uc
                if abs(s) > hu:
                    continue
                q = t * (v0 * x + v1 * y + v2) - vc
                if abs(q) > hv:
                    continue
                z_out[r, c] = t
                id_out[r, c] = p
                s_out[r, c] = s
                q_out[r, c] = q
        for c in range(w):
            x = xs[r, c]
            y = ys[r, c]
            r_out[r, c] = z_out[r, c] * np.sqrt(x * x + y * y + 1.0)


@numba.njit(parallel=True, cache=True)
def _blocked(points, prims, tol, out):  # pragma: no cover - JIT
    # True where the segment from the origin to a point crosses a rect before the point.
    for i in numba.prange(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        hit = False
        if z != z:  # NaN point
            out[i] = False
            continue
        for p in range(prims.shape[0]):
            nd = prims[p, 0] * x + prims[p, 1] * y + prims[p, 2] * z
            if nd == 0.0:
                continue
            t = prims[p, 3] / nd
            if t <= 1e-9 or t >= 1.0 - tol:
                continue
            s = t * (prims[p, 4] * x + prims[p, 5] * y + prims[p, 6] * z) - prims[p, 7]
            if abs(s) > prims[p, 12]:
                continue
            q = t * (prims[p, 8] * x + prims[p, 9] * y + prims[p, 10] * z) - prims[p, 11]
            if abs(q) > prims[p, 13]:
                continue
            hit = True
            break
        out[i] = hit


def rect_params(rects: tuple[Rect, ...], camera_from_world: RigidTransform) -> FloatArray:
    """Kernel parameters (P, 14) of rects expressed in the camera frame."""
    out = np.empty((len(rects), _N_PARAMS))
    rot = camera_from_world.rotation
    for i, r in enumerate(rects):
        c = camera_from_world.apply(r.center_m)
        n, u, v = rot @ r.normal, rot @ r.axis_u, rot @ r.axis_v
        out[i] = [*n, n @ c, *u, u @ c, *v, v @ c, r.half_u_m, r.half_v_m]
    return out


def _bbox(rect: Rect, camera_from_world: RigidTransform, intr: Intrinsics, ss: int) -> list[int]:
    """Inclusive (row0, row1, col0, col1) of the rect in the supersampled grid."""
    h, w = intr.height * ss, intr.width * ss
    pts = camera_from_world.apply(rect.boundary_m())
    if np.all(pts[:, 2] <= 0):
        return [1, 0, 1, 0]  # wholly behind the camera: empty
    if np.any(pts[:, 2] <= 1e-6):
        return [0, h - 1, 0, w - 1]
    px = intr.project(pts)
    if np.any(np.isnan(px)):
        return [0, h - 1, 0, w - 1]  # outline beyond the lens' valid radius: test everything
    g = (px + 0.5) * ss - 0.5
    margin = 2 * ss
    c0, r0 = np.floor(g.min(axis=0)).astype(int) - margin
    c1, r1 = np.ceil(g.max(axis=0)).astype(int) + margin
    return [max(r0, 0), min(r1, h - 1), max(c0, 0), min(c1, w - 1)]


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
    prims = rect_params(scene.rects, camera_from_world)
    bbox = np.array(
        [_bbox(r, camera_from_world, intr, supersample) for r in scene.rects], dtype=np.int64
    ).reshape(-1, 4)
    z, s, q, rng = (np.empty(xs.shape) for _ in range(4))
    ids = np.empty(xs.shape, dtype=np.int64)
    _cast_grid(xs, ys, prims, bbox, z, ids, s, q, rng)
    return Hits(z, ids, s, q, rng)


def blocked(
    scene: Scene, camera_from_world: RigidTransform, points_cam_m: FloatArray, tol: float = 1e-6
) -> NDArray[np.bool_]:
    """True where the line of sight from the camera centre to each point (N, 3, camera
    frame) is blocked by a rect before reaching it (relative tolerance ``tol``)."""
    prims = rect_params(scene.rects, camera_from_world)
    pts = np.ascontiguousarray(points_cam_m, dtype=np.float64).reshape(-1, 3)
    out = np.empty(pts.shape[0], dtype=np.bool_)
    _blocked(pts, prims, tol, out)
    return out.reshape(np.shape(points_cam_m)[:-1])
