"""Depth odometry: the rig's trajectory from the depth stream alone, with loop closure.

Each depth frame is registered to the current keyframe by point-to-plane ICP (Chen & Medioni
1992, "Object modelling by registration of multiple range images", Image and Vision Computing
10(3)) with projective data association (Newcombe et al. 2011, "KinectFusion: real-time dense
surface mapping and tracking", ISMAR): a point of the frame, moved by the current estimate, is
paired with the keyframe's point at the pixel it projects to. The point-to-plane error is
linearised in a small rotation and translation and solved as linear least squares (Low 2004,
"Linear least-squares optimization for point-to-plane ICP surface registration", UNC
TR04-004), coarse to fine over a pyramid of block-averaged vertex maps (stride 4, 8, 16 by
default), with Huber weights (Huber 1964) and gates on pair distance, normal angle and range.
A constant-velocity prediction starts each frame's search. Tracking against a keyframe rather
than the previous frame keeps small errors from adding up frame by frame; a new keyframe is
taken after ~10 cm or ~10 degrees of motion or when the overlap falls.

Loop closure: when a new keyframe lies near an earlier one (by the estimates: within 0.5 m and
30 degrees, and at least 10 keyframes before it), the two are registered by the same ICP
(started from the estimates' relative pose) and, when the fit passes its gates, the relative
pose becomes an edge of a pose graph over the keyframes (Lu & Milios 1997, "Globally
consistent range scan alignment for environment mapping", Autonomous Robots 4; Grisetti et al.
2010, "A tutorial on graph-based SLAM", IEEE ITS Magazine 2(4)): odometry edges between
successive keyframes plus loop edges, each weighted by its ICP's information (the Gauss-Newton
Hessian over the residual variance), optimised in rotation-vector corrections by
Levenberg-Marquardt with sparse direct solves. Every frame's pose is kept relative to its
keyframe, so it follows its keyframe when the graph moves it.

Poses are ``world_from_depth``; the world is the first frame's depth camera frame (x right, y
down, z forward), metres and seconds. The association projects through the pinhole (fx, fy,
cx, cy): a D435's depth stream is rectified (no distortion); the points themselves are
deprojected exactly (:func:`~thermodepth.camera.pixel_rays`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.sparse import csr_matrix, diags
from scipy.sparse.linalg import spsolve
from scipy.spatial.transform import Rotation

from ..camera import Intrinsics, RigidTransform, pixel_rays
from ..errors import FieldError, InputError
from ..progress import Progress
from ..trajectory import Trajectory

FloatArray = NDArray[np.float64]
Pose = FloatArray
"""A rigid transform as a (4, 4) homogeneous matrix [[R, t], [0, 1]], metres."""

_JIT: dict[str, Any] = {"cache": True, "fastmath": True, "error_model": "numpy"}
# the kernels mark "no point" by z = 0, never by NaN or inf, so fastmath's no-NaN/inf holds

_SUMS = 30  # per row: 21 Hessian (upper triangle), 6 gradient, sum r^2, inliers, sources
_SYMMETRIC = np.zeros((6, 6), np.int64)  # the full Hessian from its upper triangle's sums
_SYMMETRIC[np.triu_indices(6)] = np.arange(21)
_SYMMETRIC = np.maximum(_SYMMETRIC, _SYMMETRIC.T)
_STEP_DONE = 1e-5  # an update this small (rad, m) ends a level's iterations
_VARIANCE_FLOOR_M2 = 1e-6  # (1 mm)^2: noise-free data would otherwise weigh without bound
# a direction this much weaker than the strongest is left alone: misassociated pairs on a wall
# and floor leave sideways sliding at 3e-4 of the strongest, fitted views 2e-2 and up (measured)
_WEAK = 3e-3

# -------------------------------------------------------------------------------------------
# Kernels (numba): vertex and normal maps, and one ICP step's normal equations
# -------------------------------------------------------------------------------------------


@numba.njit(inline="always", **_JIT)
def _put_mean(out, r, c, sx, sy, sz, n, keep):  # pragma: no cover - JIT
    # out[r, c]: the block's mean point (sums sx, sy, sz of n points) where ``keep``, else 0
    if keep:
        out[r, c, 0] = sx / n
        out[r, c, 1] = sy / n
        out[r, c, 2] = sz / n
    else:
        out[r, c, 0] = 0.0
        out[r, c, 1] = 0.0
        out[r, c, 2] = 0.0


@numba.njit(parallel=True, **_JIT)
def _block_vertices(depth, scale, xs, ys, stride, max_z, jump, out):  # pragma: no cover - JIT
    # out (h, w, 3) float32: the mean of the valid points in each stride x stride block of the
    # depth image; z = 0 where under half the block has depth in range or it spans a depth
    # step (max - min > jump * min: averaging across it would make a point in mid-air).
    # xs (1, W) or (H, W), ys (H, 1) or (H, W): normalised ray coordinates (separable when
    # the camera has no distortion, so the rays cost no memory traffic).
    h, w = out.shape[0], out.shape[1]
    full_x = xs.shape[0] > 1
    full_y = ys.shape[1] > 1
    need = (stride * stride + 1) // 2
    for r in numba.prange(h):
        for c in range(w):
            sx = 0.0
            sy = 0.0
            sz = 0.0
            n = 0
            z_lo = 1e30
            z_hi = 0.0
            for i in range(r * stride, r * stride + stride):
                rx = i if full_x else 0
                for j in range(c * stride, c * stride + stride):
                    d = depth[i, j]
                    if d == 0:
                        continue
                    z = d * scale
                    if z > max_z:
                        continue
                    sx += xs[rx, j] * z
                    sy += ys[i, j if full_y else 0] * z
                    sz += z
                    n += 1
                    z_lo = min(z_lo, z)
                    z_hi = max(z_hi, z)
            _put_mean(out, r, c, sx, sy, sz, n, n >= need and z_hi - z_lo <= jump * z_lo)


@numba.njit(parallel=True, **_JIT)
def _half_vertices(v, jump, out):  # pragma: no cover - JIT
    # out (h // 2, w // 2, 3): the mean of each 2 x 2 block's valid vertices of v (h, w, 3),
    # at least 2 of them and no depth step among them; z = 0 otherwise
    for r in numba.prange(out.shape[0]):
        for c in range(out.shape[1]):
            sx = 0.0
            sy = 0.0
            sz = 0.0
            n = 0
            z_lo = 1e30
            z_hi = 0.0
            for i in range(2 * r, 2 * r + 2):
                for j in range(2 * c, 2 * c + 2):
                    z = v[i, j, 2]
                    if z > 0.0:
                        sx += v[i, j, 0]
                        sy += v[i, j, 1]
                        sz += z
                        n += 1
                        z_lo = min(z_lo, z)
                        z_hi = max(z_hi, z)
            _put_mean(out, r, c, sx, sy, sz, n, n >= 2 and z_hi - z_lo <= jump * z_lo)


@numba.njit(parallel=True, **_JIT)
def _normals(v, jump, out):  # pragma: no cover - JIT
    # out (h, w, 3): unit normals of the vertex map v (h, w, 3) from central differences,
    # turned towards the camera; 0 at the border, next to a missing vertex or a depth step
    h, w = v.shape[0], v.shape[1]
    for r in numba.prange(h):
        for c in range(w):
            out[r, c, 0] = 0.0
            out[r, c, 1] = 0.0
            out[r, c, 2] = 0.0
            if r == 0 or c == 0 or r == h - 1 or c == w - 1:
                continue
            z = v[r, c, 2]
            if z <= 0.0:
                continue
            tol = jump * z
            z_l, z_r, z_u, z_d = v[r, c - 1, 2], v[r, c + 1, 2], v[r - 1, c, 2], v[r + 1, c, 2]
            if (
                min(z_l, z_r, z_u, z_d) <= 0.0
                or max(abs(z_l - z), abs(z_r - z), abs(z_u - z), abs(z_d - z)) > tol
            ):
                continue
            ax = v[r, c + 1, 0] - v[r, c - 1, 0]
            ay = v[r, c + 1, 1] - v[r, c - 1, 1]
            az = v[r, c + 1, 2] - v[r, c - 1, 2]
            bx = v[r + 1, c, 0] - v[r - 1, c, 0]
            by = v[r + 1, c, 1] - v[r - 1, c, 1]
            bz = v[r + 1, c, 2] - v[r - 1, c, 2]
            nx = ay * bz - az * by
            ny = az * bx - ax * bz
            nz = ax * by - ay * bx
            norm = math.sqrt(nx * nx + ny * ny + nz * nz)
            if norm == 0.0:
                continue
            if nx * v[r, c, 0] + ny * v[r, c, 1] + nz * z > 0.0:
                norm = -norm
            out[r, c, 0] = nx / norm
            out[r, c, 1] = ny / norm
            out[r, c, 2] = nz / norm


@numba.njit(parallel=True, **_JIT)
def _normal_equations(src_v, src_n, dst_v, dst_n, pose, cam, gates, out):  # pragma: no cover
    # One point-to-plane step, every source row's sums in out[row] (_SUMS wide), summed by
    # the caller in a fixed order (the result does not depend on the threads).
    # pose (3, 4): dst_from_src; cam: fx, fy, cx, cy of this level's grid (a cell's centre at
    # integers); gates: max pair distance^2 (m^2), min cos of the normals' angle, Huber
    # threshold (m). A source point p moved to q = R p + t pairs with the dst vertex d and
    # normal n of the cell q projects to; r = n.(q - d), and for the update q + w x q + t the
    # Jacobian is J = [q x n, n] (Low 2004).
    h, w = src_v.shape[0], src_v.shape[1]
    hd, wd = dst_v.shape[0], dst_v.shape[1]
    fx, fy, cx, cy = cam[0], cam[1], cam[2], cam[3]
    max_d2, min_cos, huber = gates[0], gates[1], gates[2]
    for r in numba.prange(h):
        acc = out[r]
        acc[:] = 0.0
        for c in range(w):
            pz = src_v[r, c, 2]
            if pz <= 0.0:
                continue
            mx, my, mz = src_n[r, c, 0], src_n[r, c, 1], src_n[r, c, 2]
            if mx == 0.0 and my == 0.0 and mz == 0.0:
                continue
            acc[29] += 1.0
            px, py = src_v[r, c, 0], src_v[r, c, 1]
            qx = pose[0, 0] * px + pose[0, 1] * py + pose[0, 2] * pz + pose[0, 3]
            qy = pose[1, 0] * px + pose[1, 1] * py + pose[1, 2] * pz + pose[1, 3]
            qz = pose[2, 0] * px + pose[2, 1] * py + pose[2, 2] * pz + pose[2, 3]
            if qz <= 0.0:
                continue
            u = math.floor(fx * qx / qz + cx + 0.5)
            v = math.floor(fy * qy / qz + cy + 0.5)
            if u < 0 or v < 0 or u >= wd or v >= hd:
                continue
            iu, iv = int(u), int(v)
            dz = dst_v[iv, iu, 2]
            if dz <= 0.0:
                continue
            nx = np.float64(dst_n[iv, iu, 0])
            ny = np.float64(dst_n[iv, iu, 1])
            nz = np.float64(dst_n[iv, iu, 2])
            if nx == 0.0 and ny == 0.0 and nz == 0.0:
                continue
            ex = qx - dst_v[iv, iu, 0]
            ey = qy - dst_v[iv, iu, 1]
            ez = qz - dz
            if ex * ex + ey * ey + ez * ez > max_d2:
                continue
            cos = (
                nx * (pose[0, 0] * mx + pose[0, 1] * my + pose[0, 2] * mz)
                + ny * (pose[1, 0] * mx + pose[1, 1] * my + pose[1, 2] * mz)
                + nz * (pose[2, 0] * mx + pose[2, 1] * my + pose[2, 2] * mz)
            )
            if cos < min_cos:
                continue
            res = nx * ex + ny * ey + nz * ez
            wt = 1.0 if abs(res) <= huber else huber / abs(res)
            j0 = qy * nz - qz * ny
            j1 = qz * nx - qx * nz
            j2 = qx * ny - qy * nx
            jac = (j0, j1, j2, nx, ny, nz)
            k = 0
            for a in range(6):
                wa = wt * jac[a]
                for b in range(a, 6):
                    acc[k] += wa * jac[b]
                    k += 1
                acc[21 + a] += wa * res
            acc[27] += res * res
            acc[28] += 1.0


# -------------------------------------------------------------------------------------------
# Pure functions: poses, pyramids, ICP, the pose graph
# -------------------------------------------------------------------------------------------


def _pose(rotation: FloatArray, translation_m: FloatArray) -> Pose:
    m = np.eye(4)
    m[:3, :3] = rotation
    m[:3, 3] = translation_m
    return m


def _orthonormal(pose: Pose) -> Pose:
    """``pose`` with its rotation made exactly orthonormal (the nearest rotation, by SVD):
    a pose kept and composed frame after frame would otherwise drift off the rotations,
    and the transpose stop being its inverse."""
    u, _, vt = np.linalg.svd(pose[:3, :3])
    return _pose(u @ vt, pose[:3, 3])


def _inverse(pose: Pose) -> Pose:
    return _pose(pose[:3, :3].T, -pose[:3, :3].T @ pose[:3, 3])


def _exp(twist: FloatArray) -> Pose:
    """The pose of a 6-vector [rotation vector (rad), translation (m)] (Rodrigues)."""
    x, y, z, tx, ty, tz = (float(v) for v in twist)
    theta = math.sqrt(x * x + y * y + z * z)
    if theta < 1e-12:
        return np.array([[1.0, 0, 0, tx], [0, 1.0, 0, ty], [0, 0, 1.0, tz], [0, 0, 0, 1.0]])
    x, y, z = x / theta, y / theta, z / theta
    s, c = math.sin(theta), math.cos(theta)
    v = 1.0 - c
    return np.array([
        [c + x * x * v, x * y * v - z * s, x * z * v + y * s, tx],
        [x * y * v + z * s, c + y * y * v, y * z * v - x * s, ty],
        [x * z * v - y * s, y * z * v + x * s, c + z * z * v, tz],
        [0.0, 0.0, 0.0, 1.0],
    ])  # fmt: skip


def _log(pose: Pose) -> FloatArray:
    """[rotation vector (rad), translation (m)] of a pose (inverse of :func:`_exp`)."""
    return np.concatenate([Rotation.from_matrix(pose[:3, :3]).as_rotvec(), pose[:3, 3]])


def _motion(pose: Pose) -> tuple[float, float]:
    """How far a relative pose moves: (distance m, angle deg)."""
    angle = math.degrees(float(np.linalg.norm(Rotation.from_matrix(pose[:3, :3]).as_rotvec())))
    return float(np.linalg.norm(pose[:3, 3])), angle


@dataclass(frozen=True, eq=False)
class Level:
    """One pyramid level: vertices and unit normals (h, w, 3) float32 in the camera frame (m),
    z = 0 / a zero normal where there is none, and the pinhole of its grid ``cam`` (fx, fy,
    cx, cy) with cell (r, c) centred on (c, r)."""

    vertices: NDArray[np.float32]
    normals: NDArray[np.float32]
    cam: FloatArray

    @property
    def points(self) -> int:
        """How many vertices have a normal (the points ICP can use)."""
        return int(np.count_nonzero(np.any(self.normals != 0.0, axis=-1)))


def level_camera(intrinsics: Intrinsics, stride: int) -> FloatArray:
    """(fx, fy, cx, cy) of the grid of stride x stride blocks: block c spans pixels
    c s .. c s + s - 1, centred on pixel c s + (s - 1) / 2."""
    off = (stride - 1) / 2.0
    return np.array([
        intrinsics.fx / stride,
        intrinsics.fy / stride,
        (intrinsics.cx - off) / stride,
        (intrinsics.cy - off) / stride,
    ])  # fmt: skip


def _with_normals(vertices: NDArray[np.float32], cam: FloatArray, jump: float) -> Level:
    normals = np.empty_like(vertices)
    _normals(vertices, jump, normals)
    return Level(vertices, normals, cam)


def pyramid_from_vertices(
    vertices: NDArray[np.float32], cams: list[FloatArray], jump: float
) -> list[Level]:
    """Levels (finest first, one per ``cams``) from the finest level's vertices (h, w, 3),
    each next level the 2 x 2 block means of the one before (at most ``jump`` relative depth
    step inside a block)."""
    levels = [_with_normals(vertices, cams[0], jump)]
    for cam in cams[1:]:
        prev = levels[-1].vertices
        half = np.empty((prev.shape[0] // 2, prev.shape[1] // 2, 3), np.float32)
        _half_vertices(prev, jump, half)
        levels.append(_with_normals(half, cam, jump))
    return levels


def _separable_rays(intrinsics: Intrinsics) -> tuple[FloatArray, FloatArray]:
    """Normalised ray coordinates x (1, W) and y (H, 1) without distortion, else the full
    (H, W) grids of :func:`pixel_rays`."""
    if intrinsics.has_distortion:
        return pixel_rays(intrinsics)
    x = (np.arange(intrinsics.width, dtype=np.float64) - intrinsics.cx) / intrinsics.fx
    y = (np.arange(intrinsics.height, dtype=np.float64) - intrinsics.cy) / intrinsics.fy
    return x[None, :], y[:, None]


def _constrained_step(hess: FloatArray, grad: FloatArray) -> FloatArray:
    """The Gauss-Newton step -H^-1 g (6,) along the directions the data constrain.

    Directions whose eigenvalue of the scaled Hessian is under _WEAK of the largest get no
    update (Zhang, Kaess & Singh 2016, "On degeneracy of optimization-based state estimation
    problems", ICRA): they stay at the starting guess (tracking: the constant-velocity
    prediction). The rotation is scaled by the points' RMS lever arm (sqrt(tr H_rr / tr
    H_tt), m) to compare with the translation.
    """
    lever_m = math.sqrt(max(np.trace(hess[:3, :3]), 1e-300) / max(np.trace(hess[3:, 3:]), 1e-300))
    scale = np.array([1.0 / lever_m] * 3 + [1.0] * 3)
    values, vectors = np.linalg.eigh(hess * np.outer(scale, scale))
    keep = values >= _WEAK * values[-1]
    v = vectors[:, keep]
    return scale * (v @ (-(v.T @ (scale * grad)) / values[keep]))


@dataclass(frozen=True, eq=False)
class IcpResult:
    """A registration: ``pose`` dst_from_src (4, 4); ``fitness`` the fraction of the source's
    points (finest level used) paired with an inlier; ``rmse_m`` their point-to-plane RMS;
    ``inliers``; ``sources``, the source's points with a normal; ``iterations`` over all
    levels; ``information`` (6, 6), the Gauss-Newton Hessian over the residual variance, for
    the correction [rotation vector, translation] applied on the left of ``pose`` (1 / rad^2,
    1 / m^2)."""

    pose: Pose
    fitness: float
    rmse_m: float
    inliers: int
    sources: int
    iterations: int
    information: FloatArray


def register(
    src: list[Level],
    dst: list[Level],
    init: Pose,
    iterations: tuple[int, ...],
    pair_distance_m: tuple[float, ...],
    normal_angle_deg: float,
    huber_m: float,
) -> IcpResult:
    """Point-to-plane ICP of ``src`` onto ``dst`` (levels finest first, as many as
    ``iterations``; run coarsest first) from ``init`` (dst_from_src, (4, 4)): at each step
    the Huber-weighted normal equations of :func:`_normal_equations` (Low 2004), solved by
    :func:`_constrained_step` for a small motion applied on the left, until ``iterations``
    steps or a step under 1e-5 rad and m. Pairs are gated at ``pair_distance_m`` apart (per
    level), ``normal_angle_deg`` between normals; ``huber_m`` is the Huber threshold."""
    pose = init.copy()
    min_cos = math.cos(math.radians(normal_angle_deg))
    sums = np.zeros(_SUMS)
    hess = np.zeros((6, 6))
    done = 0
    for lvl in range(len(iterations) - 1, -1, -1):
        s, d = src[lvl], dst[lvl]
        gates = np.array([pair_distance_m[lvl] ** 2, min_cos, huber_m])
        out = np.empty((s.vertices.shape[0], _SUMS))
        for _ in range(iterations[lvl]):
            _normal_equations(
                s.vertices, s.normals, d.vertices, d.normals, pose[:3], d.cam, gates, out
            )
            sums = out.sum(axis=0)
            done += 1
            hess = sums[_SYMMETRIC]
            if sums[28] < 6:
                break
            step = _constrained_step(hess, sums[21:27])
            pose = _exp(step) @ pose
            if np.all(np.abs(step) < _STEP_DONE):
                break
    inliers = int(sums[28])
    variance = max(sums[27] / max(inliers, 1), _VARIANCE_FLOOR_M2)
    return IcpResult(
        pose=pose,
        fitness=float(sums[28] / sums[29]) if sums[29] > 0 else 0.0,
        rmse_m=float(math.sqrt(sums[27] / inliers)) if inliers else math.inf,
        inliers=inliers,
        sources=int(sums[29]),
        iterations=done,
        information=hess / variance if inliers >= 6 else np.zeros((6, 6)),
    )


def _levenberg_marquardt(
    residuals: Callable[[FloatArray], FloatArray],
    jacobian: Callable[[FloatArray], csr_matrix],
    x: FloatArray,
    max_iterations: int = 30,
) -> FloatArray:
    """The x minimising |residuals(x)|^2 from ``x``, by Levenberg-Marquardt (Levenberg 1944,
    Marquardt 1963: steps (J^T J + lambda diag(J^T J)) dx = -J^T r, lambda shrunk after a
    step that lowers the cost, grown after one that does not) with a direct sparse solve.

    scipy's least_squares solves a sparse problem's steps iteratively (LSMR), which converges
    slowly on a pose graph's long chains: 0.9 s for 500 keyframes, against 0.05 s here to a
    lower cost (measured). Stops when a step lowers the cost by under 1e-10 of it.
    """
    r = residuals(x)
    cost = float(r @ r)
    damping = 1e-4
    for _ in range(max_iterations):
        jac = jacobian(x)
        normal = (jac.T @ jac).tocsc()
        grad = jac.T @ r
        while damping < 1e10:
            step = spsolve(normal + damping * diags(normal.diagonal()), -grad)
            r_new = residuals(x + step)
            cost_new = float(r_new @ r_new)
            if cost_new < cost:
                break
            damping *= 10.0
        else:
            return x
        x, r, done = x + step, r_new, cost - cost_new < 1e-10 * cost
        cost, damping = cost_new, damping / 10.0
        if done:
            break
    return x


def _skew(v: FloatArray) -> FloatArray:
    """Cross-product matrices (N, 3, 3) of vectors (N, 3): skew(a) @ b = a x b."""
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    out[..., 1, 0], out[..., 2, 0], out[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return out


def _left_jacobians(phi: FloatArray) -> tuple[FloatArray, FloatArray]:
    """SO(3)'s left Jacobian J_l and its inverse (N, 3, 3) at rotation vectors phi (N, 3):
    exp(phi + d) = exp(J_l d) exp(phi), log(exp(d) exp(phi)) = phi + J_l^-1 d to first order
    (Barfoot 2017, "State estimation for robotics", eqs. 7.77, 7.79)."""
    theta = np.linalg.norm(phi, axis=-1)[:, None, None]
    k = _skew(phi)
    kk = k @ k
    small = theta < 1e-6
    t = np.where(small, 1.0, theta)
    a = np.where(small, 0.5, (1.0 - np.cos(t)) / t**2)
    b = np.where(small, 1.0 / 6.0, (t - np.sin(t)) / t**3)
    c = np.where(small, 1.0 / 12.0, (1.0 - t * np.sin(t) / (2.0 * (1.0 - np.cos(t)))) / t**2)
    return np.eye(3) + a * k + b * kk, np.eye(3) - 0.5 * k + c * kk


def optimise_pose_graph(
    poses: FloatArray,
    edges: NDArray[np.int64],
    measured: FloatArray,
    information: FloatArray,
) -> FloatArray:
    """Optimised poses (K, 4, 4) of a pose graph (Lu & Milios 1997; Grisetti et al. 2010).

    poses: (K, 4, 4) ``world_from_node`` estimates, node 0 held fixed (it fixes the world);
    edges: (E, 2) node pairs (i, j); measured: (E, 4, 4) ``i_from_j`` each edge measured;
    information: (E, 6, 6) each measurement's information for the error e = [rotation
    vector, translation] of E = ``estimate @ measured^-1`` (in node i's frame). Minimises
    the sum of e^T information e over the edges, in corrections [rotation vector a,
    translation b] applied on the left of each pose (R <- exp(a) R, t <- exp(a) t + b), by
    :func:`_levenberg_marquardt` with the analytic sparse Jacobian: moving node j on the left
    by x_j moves E on the left by M_i x_j, M_i = [[R_i^T, 0], [-R_i^T [t_i]x, R_i^T]], node i
    by x_i by -M_i x_i; and e by [[J_l^-1(e_r), 0], [-[t_E]x, I]] of that.
    """
    k, n_e = len(poses), len(edges)
    if k < 2 or n_e == 0:
        return poses.copy()
    # sqrt of the information, upper: e^T L L^T e = |L^T e|^2 (a floor keeps it positive
    # definite when a view left a direction unconstrained)
    floor = 1e-9 * np.trace(information, axis1=1, axis2=2)[:, None, None] * np.eye(6)
    sqrt_t = np.transpose(np.linalg.cholesky(information + floor), (0, 2, 1))
    inv_meas = np.array([_inverse(m) for m in measured])
    rot0, pos0 = poses[:, :3, :3], poses[:, :3, 3]
    i, j = edges[:, 0], edges[:, 1]
    # the Jacobian's nonzeros: per edge a 6 x 6 block for node i (-B) and node j (+B), rows
    # 6 e + r and columns 6 (node - 1) + c; node 0 is fixed and has no columns
    rows = np.broadcast_to(6 * np.arange(n_e)[:, None, None] + np.arange(6)[:, None], (n_e, 6, 6))
    cols_i = np.broadcast_to(6 * (i - 1)[:, None, None] + np.arange(6), rows.shape)
    cols_j = np.broadcast_to(6 * (j - 1)[:, None, None] + np.arange(6), rows.shape)
    keep_i = np.broadcast_to(i[:, None, None] > 0, rows.shape)
    keep_j = np.broadcast_to(j[:, None, None] > 0, rows.shape)

    def corrected(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        d = np.vstack([np.zeros(6), x.reshape(k - 1, 6)])
        dr = Rotation.from_rotvec(d[:, :3]).as_matrix()
        return dr @ rot0, np.einsum("kab,kb->ka", dr, pos0) + d[:, 3:]

    def errors(x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """e (E, 6), R_i (E, 3, 3), t_i (E, 3)."""
        rot, pos = corrected(x)
        rel_r = np.einsum("eba,ebc->eac", rot[i], rot[j])  # R_i^T R_j
        rel_t = np.einsum("eba,eb->ea", rot[i], pos[j] - pos[i])
        err_r = rel_r @ inv_meas[:, :3, :3]
        err_t = np.einsum("eab,eb->ea", rel_r, inv_meas[:, :3, 3]) + rel_t
        return np.hstack([Rotation.from_matrix(err_r).as_rotvec(), err_t]), rot[i], pos[i]

    def residuals(x: FloatArray) -> FloatArray:
        return np.einsum("eab,eb->ea", sqrt_t, errors(x)[0]).ravel()

    def jacobian(x: FloatArray) -> csr_matrix:
        err, rot_i, pos_i = errors(x)
        rt = np.transpose(rot_i, (0, 2, 1))
        m = np.zeros((n_e, 6, 6))
        m[:, :3, :3] = m[:, 3:, 3:] = rt
        m[:, 3:, :3] = -rt @ _skew(pos_i)
        g = np.tile(np.eye(6), (n_e, 1, 1))
        g[:, :3, :3] = _left_jacobians(err[:, :3])[1]
        g[:, 3:, :3] = -_skew(err[:, 3:])
        b = sqrt_t @ g @ m
        # x moves node k on the left by N_k x: [[J_l(a), 0], [[b]x J_l(a), I]]
        d = np.vstack([np.zeros(6), x.reshape(k - 1, 6)])
        n = np.tile(np.eye(6), (k, 1, 1))
        n[:, :3, :3] = _left_jacobians(d[:, :3])[0]
        n[:, 3:, :3] = _skew(d[:, 3:]) @ n[:, :3, :3]
        data = np.concatenate([-(b @ n[i])[keep_i], (b @ n[j])[keep_j]])
        r = np.concatenate([rows[keep_i], rows[keep_j]])
        c = np.concatenate([cols_i[keep_i], cols_j[keep_j]])
        return csr_matrix((data, (r, c)), shape=(6 * n_e, 6 * (k - 1)))

    rot, pos = corrected(_levenberg_marquardt(residuals, jacobian, np.zeros(6 * (k - 1))))
    out = np.tile(np.eye(4), (k, 1, 1))
    out[:, :3, :3] = rot
    out[:, :3, 3] = pos
    return out


# -------------------------------------------------------------------------------------------
# Options, diagnostics and the tracker
# -------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class OdometryOptions:
    """How :func:`depth_odometry` tracks (lengths in metres, angles in degrees).

    - Pyramid: ``stride_px``, the finest level's block side in pixels (4: 320 x 180 points
      at 1280 x 720); ``iterations``, ICP steps per level, finest first (as many levels, each
      of twice the stride before); depth beyond ``max_range_m`` is ignored (the D435's error
      grows as z^2, but a hall's far walls fix what a few near surfaces leave free: 4 m lost
      the machine walk of :mod:`~thermodepth.sim.walkaround`, 6 m tracks it to 2 mm); a
      relative depth step over ``edge_jump`` (of z) splits neighbours: no block mean or
      normal across it.
    - Pairs: gated at ``pair_distance_m`` apart and ``normal_angle_deg`` between normals;
      Huber weights past ``huber_m`` of point-to-plane residual.
    - Keyframes: a new one after ``keyframe_distance_m`` or ``keyframe_angle_deg`` of motion
      from the current one, or when under ``keyframe_fitness`` of a frame's points pair.
    - Lost tracking: a frame with under ``min_points`` points (of the finest level), or a fit
      pairing under ``min_points`` or ``min_fitness`` of them. Its pose follows the
      constant-velocity prediction for ``lost_predict_frames`` frames in a row, then is held;
      a held frame with depth that does not fit starts a new keyframe there, tied to the last
      by a weak edge that a loop closure can correct.
    - Loop closure (``loop_closure``): a new keyframe within ``loop_distance_m`` and
      ``loop_angle_deg`` of one at least ``loop_min_keyframes_apart`` keyframes before it is
      registered to it (level 1 and coarser, ``loop_iterations`` steps per level, pairs gated
      at ``loop_pair_distance_m`` on the coarsest level down to ``pair_distance_m``), and
      accepted when the fit pairs ``loop_min_fitness`` of the points at ``loop_max_rmse_m``
      RMS or less.
    """

    stride_px: int = 4
    # one step at the finest level: the coarse levels have converged by then (both simulated
    # walks: ATE within 0.2 mm of (3, 4, 6), a third faster)
    iterations: tuple[int, ...] = (1, 3, 5)
    max_range_m: float = 6.0
    edge_jump: float = 0.07
    pair_distance_m: float = 0.10
    normal_angle_deg: float = 30.0
    huber_m: float = 0.01
    keyframe_distance_m: float = 0.10
    keyframe_angle_deg: float = 10.0
    keyframe_fitness: float = 0.7
    min_points: int = 300
    min_fitness: float = 0.3
    lost_predict_frames: int = 5
    loop_closure: bool = True
    loop_distance_m: float = 0.5
    loop_angle_deg: float = 30.0
    loop_min_keyframes_apart: int = 10
    loop_iterations: int = 15
    loop_pair_distance_m: float = 0.30
    loop_min_fitness: float = 0.4
    loop_max_rmse_m: float = 0.02

    def __post_init__(self) -> None:
        if self.stride_px < 1:
            raise FieldError("stride_px", f"must be at least 1, got {self.stride_px}")
        if not self.iterations or min(self.iterations) < 1:
            raise FieldError("iterations", f"one or more levels of >= 1, got {self.iterations}")
        for name in (
            "max_range_m",
            "edge_jump",
            "pair_distance_m",
            "huber_m",
            "loop_pair_distance_m",
            "loop_max_rmse_m",
        ):
            if not getattr(self, name) > 0:
                raise FieldError(name, f"must be positive, got {getattr(self, name)}")
        for name in ("keyframe_fitness", "min_fitness", "loop_min_fitness"):
            if not 0 <= getattr(self, name) <= 1:
                raise FieldError(name, f"must be in [0, 1], got {getattr(self, name)}")

    @property
    def levels(self) -> int:
        return len(self.iterations)

    @property
    def loop_level(self) -> int:
        """The finest level loop closure registers on (1, or 0 with a one-level pyramid)."""
        return min(1, self.levels - 1)


@dataclass(frozen=True)
class LostFrame:
    """A frame tracking failed on: its index, time (s), why, and what its pose became
    (``"constant velocity"``: predicted from the motion before; ``"held"``: the last pose;
    ``"restarted: ..."``: held, and tracking starts afresh from it as a new keyframe)."""

    frame: int
    time_s: float
    reason: str
    action: str


@dataclass(frozen=True)
class LoopClosure:
    """A loop closure tried: keyframe ``keyframe`` (frame ``frame``) registered to the earlier
    keyframe ``earlier`` (frame ``earlier_frame``); the fit's fitness and RMSE (m); how far
    the fit moved the estimates' relative pose (``correction_m``, ``correction_deg``: the
    drift it found); ``accepted`` and, if not, why."""

    keyframe: int
    earlier: int
    frame: int
    earlier_frame: int
    fitness: float
    rmse_m: float
    correction_m: float
    correction_deg: float
    accepted: bool
    reason: str = ""


@dataclass(frozen=True, eq=False)
class Odometry:
    """What :func:`depth_odometry` found.

    trajectory: ``world_from_depth`` at every frame's time (world = the first frame's camera
    frame); per frame (N,): ``fitness`` (fraction of its points paired with an inlier, NaN
    where not tracked), ``rmse_m`` (point-to-plane RMS of the inliers, NaN where not tracked),
    ``iterations`` (ICP steps), ``keyframe_of_frame`` (the keyframe its pose hangs from; -1
    before the first keyframe: frames without depth at the start, held at the world's origin);
    ``keyframes``: the frame index of each keyframe; ``loops``: every loop closure tried;
    ``lost``: the frames tracking failed on.
    """

    trajectory: Trajectory
    fitness: FloatArray
    rmse_m: FloatArray
    iterations: NDArray[np.int64]
    keyframe_of_frame: NDArray[np.int64]
    keyframes: tuple[int, ...]
    loops: tuple[LoopClosure, ...]
    lost: tuple[LostFrame, ...]

    @property
    def accepted_loops(self) -> tuple[LoopClosure, ...]:
        return tuple(lc for lc in self.loops if lc.accepted)

    def summary(self) -> dict[str, Any]:
        """The diagnostics in brief, JSON-ready: poses, keyframes, loop closures tried and
        accepted, the median fitness and RMSE (m) of the tracked frames (None: none), and the
        lost frames by what was done."""
        tracked = np.isfinite(self.fitness)
        actions = [lf.action.split(":")[0] for lf in self.lost]
        return {
            "poses": len(self.trajectory),
            "keyframes": len(self.keyframes),
            "loop_closures": {"tried": len(self.loops), "accepted": len(self.accepted_loops)},
            "fitness_median": float(np.median(self.fitness[tracked])) if tracked.any() else None,
            "rmse_median_m": float(np.median(self.rmse_m[tracked])) if tracked.any() else None,
            "lost_frames": {a: actions.count(a) for a in sorted(set(actions))},
        }


@dataclass(eq=False)
class _Keyframe:
    frame: int
    pose: Pose  # world_from_keyframe
    loop_vertices: NDArray[np.float32]  # its vertices at the options' loop level


@dataclass(eq=False)
class DepthOdometry:
    """Depth odometry one frame at a time: :meth:`track` each frame in time order, then
    :meth:`result`. ``intrinsics`` of the depth image, ``depth_scale_m`` metres per unit."""

    intrinsics: Intrinsics
    depth_scale_m: float
    options: OdometryOptions = field(default_factory=OdometryOptions)

    def __post_init__(self) -> None:
        if not self.depth_scale_m > 0:
            raise FieldError("depth_scale_m", f"must be positive, got {self.depth_scale_m}")
        o = self.options
        self._strides = [o.stride_px * 2**k for k in range(o.levels)]
        if self.intrinsics.width // self._strides[-1] < 3:
            raise FieldError(
                "iterations",
                "too many levels for the image: the coarsest would be under 3 blocks wide",
            )
        self._cams = [level_camera(self.intrinsics, s) for s in self._strides]
        self._xs, self._ys = _separable_rays(self.intrinsics)
        self._times: list[float] = []
        self._refs: list[int] = []  # each frame's keyframe (-1: none yet, the world's origin)
        self._rels: list[Pose] = []  # each frame's keyframe_from_depth
        self._fitness: list[float] = []
        self._rmse: list[float] = []
        self._iters: list[int] = []
        self._keyframes: list[_Keyframe] = []
        self._active: list[Level] = []  # the current keyframe's pyramid
        self._edges: list[tuple[int, int]] = []
        self._measured: list[Pose] = []
        self._information: list[FloatArray] = []
        self._loops: list[LoopClosure] = []
        self._lost: list[LostFrame] = []
        self._velocity: tuple[Pose, float] | None = None  # prev_from_current over dt (s)
        self._lost_run = 0

    # -- the pieces ----------------------------------------------------------------------

    def pyramid(self, depth: NDArray[np.uint16]) -> list[Level]:
        """The levels (finest first) of a depth frame (H, W) in the options' units."""
        o = self.options
        s = self._strides[0]
        h, w = self.intrinsics.height // s, self.intrinsics.width // s
        finest = np.empty((h, w, 3), np.float32)
        _block_vertices(
            depth, self.depth_scale_m, self._xs, self._ys, s, o.max_range_m, o.edge_jump, finest
        )
        return pyramid_from_vertices(finest, self._cams, o.edge_jump)

    def _world(self, frame: int) -> Pose:
        ref = self._refs[frame]
        return self._rels[frame] if ref < 0 else self._keyframes[ref].pose @ self._rels[frame]

    def _predicted(self, time_s: float) -> tuple[Pose, str]:
        """The pose at ``time_s`` by constant velocity from the last frame (held without a
        motion to go by), and which of the two it is."""
        last = self._world(len(self._times) - 1)
        if self._velocity is None or self._lost_run >= self.options.lost_predict_frames:
            return last, "held"
        delta, dt = self._velocity
        scale = (time_s - self._times[-1]) / dt
        return last @ _exp(_log(delta) * scale), "constant velocity"

    def _record(self, time_s: float, ref: int, rel: Pose, fit: IcpResult | None) -> None:
        self._times.append(time_s)
        self._refs.append(ref)
        self._rels.append(_orthonormal(rel))
        self._fitness.append(fit.fitness if fit else math.nan)
        self._rmse.append(fit.rmse_m if fit else math.nan)
        self._iters.append(fit.iterations if fit else 0)

    def _lose(self, time_s: float, reason: str, action: str) -> None:
        self._lost.append(LostFrame(len(self._times), time_s, reason, action))
        self._lost_run += 1

    def _new_keyframe(self, levels: list[Level], pose: Pose) -> None:
        """The last frame recorded becomes a keyframe at ``pose`` (``world_from_depth``)."""
        lvl = levels[self.options.loop_level].vertices
        self._keyframes.append(_Keyframe(len(self._times) - 1, _orthonormal(pose), lvl))
        self._active = levels
        self._refs[-1], self._rels[-1] = len(self._keyframes) - 1, np.eye(4)

    # -- tracking ------------------------------------------------------------------------

    def track(self, time_s: float, depth: NDArray[np.uint16]) -> RigidTransform:
        """Track the next frame (``depth`` (H, W) in units of ``depth_scale_m``, 0 = none, at
        ``time_s``, after the last frame's); returns its pose ``world_from_depth`` as
        estimated now (loop closures may move it later: :meth:`result` has the final)."""
        n = len(self._times)
        depth = np.asarray(depth)
        if depth.dtype != np.uint16:
            raise InputError(f"depth frame {n}: {depth.dtype} pixels, depth is uint16")
        if depth.shape != self.intrinsics.shape:
            raise InputError(
                f"depth frame {n}: shape {depth.shape}, the camera's is {self.intrinsics.shape}"
            )
        if self._times and not time_s > self._times[-1]:
            raise InputError(
                f"depth frame {n}: time {time_s} s does not follow {self._times[-1]} s"
            )
        o = self.options
        levels = self.pyramid(np.ascontiguousarray(depth))
        if not self._keyframes:  # the first frame with depth starts the world
            self._record(time_s, -1, np.eye(4), None)
            if levels[0].points >= o.min_points:
                self._new_keyframe(levels, np.eye(4))
            else:
                self._lost.append(LostFrame(n, time_s, "no depth to start from", "held"))
            return self.pose(n)
        kf, kf_pose = len(self._keyframes) - 1, self._keyframes[-1].pose
        guess, action = self._predicted(time_s)
        init = _inverse(kf_pose) @ guess
        last = self._world(n - 1)
        fit = register(
            levels,
            self._active,
            init,
            o.iterations,
            (o.pair_distance_m,) * o.levels,
            o.normal_angle_deg,
            o.huber_m,
        )
        if fit.sources < o.min_points:
            reason = f"{fit.sources} points with depth (min_points {o.min_points})"
        elif fit.inliers < o.min_points or fit.fitness < o.min_fitness:
            reason = f"poor fit: fitness {fit.fitness:.2f}, {fit.inliers} inliers"
        else:
            self._record(time_s, kf, fit.pose, fit)
            self._lost_run = 0
            current = kf_pose @ fit.pose
            self._velocity = (_inverse(last) @ current, time_s - self._times[-2])
            distance_m, angle_deg = _motion(fit.pose)
            if (
                distance_m > o.keyframe_distance_m
                or angle_deg > o.keyframe_angle_deg
                or fit.fitness < o.keyframe_fitness
            ):
                self._link(kf, fit.pose, fit.information)
                self._new_keyframe(levels, current)
                if o.loop_closure:
                    self._close_loop(kf + 1, levels)
            return self.pose(n)
        restart = action == "held" and fit.sources >= o.min_points
        if restart:  # lost too long for the prediction to find the way back: start afresh
            action = "restarted: a new keyframe at the held pose"
        self._lose(time_s, reason, action)
        self._record(time_s, kf, init, None)
        if action != "constant velocity":
            self._velocity = None
        if restart:
            # a weak edge (1 m, 1 rad) keeps the graph in one piece until a loop ties it
            self._link(kf, init, np.eye(6))
            self._new_keyframe(levels, guess)
            self._lost_run = 0
        return self.pose(n)

    def _link(self, kf: int, measured: Pose, information: FloatArray) -> None:
        """An odometry edge from keyframe ``kf`` to the next, ``kf_from_next`` measured."""
        self._edges.append((kf, kf + 1))
        self._measured.append(measured)
        self._information.append(information)

    def pose(self, frame: int) -> RigidTransform:
        """Frame ``frame``'s pose ``world_from_depth`` as estimated now."""
        w = self._world(frame)
        return RigidTransform(w[:3, :3], w[:3, 3], "world", "depth")

    # -- loop closure --------------------------------------------------------------------

    def _close_loop(self, kf: int, levels: list[Level]) -> None:
        """Try to close a loop from keyframe ``kf`` (pyramid ``levels``) to the nearest
        earlier keyframe within the gates; on success add the edge and optimise the graph."""
        o = self.options
        here = self._keyframes[kf].pose
        last = kf - o.loop_min_keyframes_apart  # the latest keyframe far enough back
        if last < 0:
            return
        before = np.array([k.pose for k in self._keyframes[: last + 1]])
        distance_m = np.linalg.norm(before[:, :3, 3] - here[:3, 3], axis=1)
        cos = (np.einsum("kij,ij->k", before[:, :3, :3], here[:3, :3]) - 1.0) / 2.0  # tr R_k^T R
        near = (distance_m <= o.loop_distance_m) & (cos >= math.cos(math.radians(o.loop_angle_deg)))
        if not near.any():
            return
        best = int(np.argmin(np.where(near, distance_m, np.inf)))
        earlier = self._keyframes[best]
        lvl = o.loop_level
        dst = pyramid_from_vertices(earlier.loop_vertices, self._cams[lvl:], o.edge_jump)
        init = _inverse(earlier.pose) @ here
        n = o.levels - lvl
        gates = tuple(np.geomspace(o.pair_distance_m, o.loop_pair_distance_m, n))
        fit = register(
            levels[lvl:],
            dst,
            init,
            (o.loop_iterations,) * n,
            gates,
            o.normal_angle_deg,
            o.huber_m,
        )
        correction_m, correction_deg = _motion(fit.pose @ _inverse(init))
        reason = ""
        if fit.fitness < o.loop_min_fitness:
            reason = f"fitness {fit.fitness:.2f} < {o.loop_min_fitness}"
        elif fit.rmse_m > o.loop_max_rmse_m:
            reason = f"rmse {fit.rmse_m * 1e3:.1f} mm > {o.loop_max_rmse_m * 1e3:.1f} mm"
        self._loops.append(
            LoopClosure(
                kf,
                best,
                self._keyframes[kf].frame,
                earlier.frame,
                fit.fitness,
                fit.rmse_m,
                correction_m,
                correction_deg,
                not reason,
                reason,
            )
        )
        if reason:
            return
        self._edges.append((best, kf))
        self._measured.append(fit.pose)
        self._information.append(fit.information)
        poses = optimise_pose_graph(
            np.array([k.pose for k in self._keyframes]),
            np.array(self._edges, dtype=np.int64),
            np.array(self._measured),
            np.array(self._information),
        )
        for k, p in zip(self._keyframes, poses, strict=True):
            k.pose = p

    # -- the result ----------------------------------------------------------------------

    def result(self) -> Odometry:
        """The trajectory and diagnostics of the frames tracked so far (one or more)."""
        if not self._times:
            raise InputError("depth odometry: no frames")
        poses = np.array([self._world(f) for f in range(len(self._times))])
        return Odometry(
            trajectory=Trajectory(np.array(self._times), poses[:, :3, :3], poses[:, :3, 3]),
            fitness=np.array(self._fitness),
            rmse_m=np.array(self._rmse),
            iterations=np.array(self._iters, dtype=np.int64),
            keyframe_of_frame=np.array(self._refs, dtype=np.int64),
            keyframes=tuple(k.frame for k in self._keyframes),
            loops=tuple(self._loops),
            lost=tuple(self._lost),
        )


def depth_odometry(
    frames: Iterable[tuple[float, NDArray[np.uint16]]],
    intrinsics: Intrinsics,
    depth_scale_m: float,
    options: OdometryOptions | None = None,
    progress: Progress | None = None,
) -> Odometry:
    """The depth camera's trajectory from its frames alone (module docstring).

    frames: ``(time_s, depth)`` in time order, depth (H, W) uint16 in units of
    ``depth_scale_m`` metres, 0 = no depth; ``intrinsics`` of the depth image; ``progress``
    told of each frame tracked. Returns the poses ``world_from_depth`` (world = the first
    frame's camera frame; the first with depth, if frames before it have none) at every
    frame's time, with per-frame fits, keyframes, loop closures and the frames where tracking
    was lost. Memory: a keyframe keeps its stride-8 vertex map for loop closure (170 kB at
    1280 x 720), a frame its pose.
    """
    odo = DepthOdometry(intrinsics, depth_scale_m, options or OdometryOptions())
    for time_s, depth in frames:
        odo.track(float(time_s), depth)
        if progress is not None:
            progress(1)
    return odo.result()
