"""Ray casting of rect scenes for a pinhole camera with distortion, and of arbitrary rays
(numba kernels).

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
from .scene import Scene

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


@numba.njit(parallel=True, cache=True)
def _cast_rays(origins, dirs, skip, prims, t_out, id_out, s_out, q_out):  # pragma: no cover
    # the nearest rect along each ray o + t d (t > 0), all rects tested: rays go anywhere
    for i in numba.prange(origins.shape[0]):
        ox, oy, oz = origins[i, 0], origins[i, 1], origins[i, 2]
        dx, dy, dz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        best = np.inf
        best_p = -1
        best_s = np.nan
        best_q = np.nan
        for p in range(prims.shape[0]):
            if p == skip[i]:
                continue
            nd = prims[p, 0] * dx + prims[p, 1] * dy + prims[p, 2] * dz
            if nd == 0.0:
                continue
            t = (prims[p, 3] - (prims[p, 0] * ox + prims[p, 1] * oy + prims[p, 2] * oz)) / nd
            if t <= 1e-9 or t >= best:
                continue
            x, y, z = ox + t * dx, oy + t * dy, oz + t * dz
            s = prims[p, 4] * x + prims[p, 5] * y + prims[p, 6] * z - prims[p, 7]
            if abs(s) > prims[p, 12]:
                continue
            q = prims[p, 8] * x + prims[p, 9] * y + prims[p, 10] * z - prims[p, 11]
            if abs(q) > prims[p, 13]:
                continue
            best, best_p, best_s, best_q = t, p, s, q
        t_out[i] = best
        id_out[i] = best_p
        s_out[i] = best_s
        q_out[i] = best_q


def rect_params(scene: Scene, camera_from_world: RigidTransform) -> FloatArray:
    """Kernel parameters (R, 14) of the scene's rects expressed in the camera frame."""
    out = np.empty((len(scene.rects), _N_PARAMS))
    rot, t = camera_from_world.rotation, camera_from_world.translation_m
    normals = scene.geometry.normal
    # one rect at a time: products of whole arrays would round a last bit differently
    for i, r in enumerate(scene.rects):
        c = r.center_m @ rot.T + t
        n, u, v = rot @ normals[i], rot @ r.axis_u, rot @ r.axis_v
        out[i] = [*n, n @ c, *u, u @ c, *v, v @ c, r.half_u_m, r.half_v_m]
    return out


def _bboxes(
    scene: Scene, camera_from_world: RigidTransform, intr: Intrinsics, ss: int
) -> NDArray[np.int64]:
    """Inclusive (row0, row1, col0, col1) of each rect in the supersampled grid, (R, 4):
    the bounds of its projected outline plus a margin; the whole grid where the outline
    reaches behind the camera or beyond the lens' valid radius, nothing where it is wholly
    behind."""
    h, w = intr.height * ss, intr.width * ss
    pts = camera_from_world.apply(scene.outlines_m)  # (R, P, 3)
    z = pts[..., 2]
    px = intr.project(pts)
    g = (np.nan_to_num(px) + 0.5) * ss - 0.5
    margin = 2 * ss
    c0, r0 = (np.floor(g.min(axis=1)).astype(np.int64) - margin).T
    c1, r1 = (np.ceil(g.max(axis=1)).astype(np.int64) + margin).T
    out = np.stack(
        [np.maximum(r0, 0), np.minimum(r1, h - 1), np.maximum(c0, 0), np.minimum(c1, w - 1)],
        axis=1,
    )
    out[np.any(z <= 1e-6, axis=1) | np.any(np.isnan(px), axis=(1, 2))] = [0, h - 1, 0, w - 1]
    out[np.all(z <= 0, axis=1)] = [1, 0, 1, 0]  # empty
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
    prims = rect_params(scene, camera_from_world)
    bbox = _bboxes(scene, camera_from_world, intr, supersample)
    z, s, q, rng = (np.empty(xs.shape) for _ in range(4))
    ids = np.empty(xs.shape, dtype=np.int64)
    _cast_grid(xs, ys, prims, bbox, z, ids, s, q, rng)
    return Hits(z, ids, s, q, rng)


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
    _cast_rays(o, d, skip, prims, t, ids, s, q)
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
    if in_image is not None:
        r0, r1, c0, c1 = _bboxes(scene, camera_from_world, in_image, 1).T
        prims = np.ascontiguousarray(prims[(r0 <= r1) & (c0 <= c1)])
    pts = np.ascontiguousarray(points_cam_m, dtype=np.float64).reshape(-1, 3)
    out = np.empty(pts.shape[0], dtype=np.bool_)
    _blocked(pts, prims, tol, out)
    return out.reshape(np.shape(points_cam_m)[:-1])
