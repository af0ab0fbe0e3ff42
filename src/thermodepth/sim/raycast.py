"""Ray casting of rect scenes for a pinhole camera with distortion, and of arbitrary rays
(numba kernels of :mod:`.kernels`).

A camera's rays are given as a grid of undistorted normalised coordinates (x, y): the ray
through a (sub)pixel is d = (x, y, 1) in the camera frame, so the hit parameter t is the depth
Z along the optical axis and the range is t |d|. Each rect is tested only inside the
(sub)pixel bounding box of its projected outline; the nearest hit wins (z-buffer).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..camera import Intrinsics, RigidTransform, pixel_rays
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
    if in_image is not None:
        r0, r1, c0, c1 = _bboxes(scene, camera_from_world, in_image, 1).T
        prims = np.ascontiguousarray(prims[(r0 <= r1) & (c0 <= c1)])
    pts = np.ascontiguousarray(points_cam_m, dtype=np.float64).reshape(-1, 3)
    out = np.empty(pts.shape[0], dtype=np.bool_)
    kernels.blocked(pts, prims, tol, out)
    return out.reshape(np.shape(points_cam_m)[:-1])
