"""The fused geometry: a truncated signed distance function (TSDF) on a voxel grid, and the
surface mesh extracted from it.

Each depth frame, at its pose, updates the voxels near the surfaces it sees with the signed
distance along the camera's axis, truncated at ``trunc_m`` and averaged over frames (Curless
& Levoy, SIGGRAPH 1996; the projective form of Newcombe et al., KinectFusion, ISMAR 2011).
Only the 8x8x8-voxel blocks that a frame's depth points reach are visited, in parallel, each
voxel projected into the depth image (no two threads write one voxel). The zero level set is
meshed by marching cubes (Lewiner et al. 2003, scikit-image) over the cubes whose eight
corners were all observed: an unobserved corner would otherwise make a false wall between
what was seen behind a surface and what never was.

Grid: voxel (i, j, k) has its centre at ``origin_m + (i, j, k) * voxel_m`` in the grid's own
frame (metres), which ``grid_from_world`` places in the world: :meth:`Volume.of_points` turns
the grid to the smallest box round the points (a trajectory's world is often its first camera,
tilted; a box square to that would hold twice the voxels). tsdf is in units of ``trunc_m``
(-1 .. 1, positive in front of a surface, 1 where unobserved); weight counts the frames that
observed a voxel.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..camera import Intrinsics, RigidTransform
from ..errors import InputError
from ..registration.kernels import Lens, project_point

FloatArray = NDArray[np.float64]
BLOCK = 8  # voxels per block side
MAX_VOXELS = 400_000_000  # 3.2 GB of tsdf and weight: a box bigger than this is a mistake
# fastmath without "nnan" and "ninf": the kernels test for NaN (no temperature) and inf (no
# surface), which those flags would let LLVM fold away
_JIT: dict[str, Any] = {
    "cache": True,
    "fastmath": {"nsz", "arcp", "contract", "afn"},
    "error_model": "numpy",
}


def lens_for(intr: Intrinsics) -> Lens:
    """A camera as the registration's kernels project with it, at zero translation: points
    are given in the camera's own frame."""
    values = (
        *(0.0, 0.0, 0.0, intr.fx, intr.fy, intr.cx, intr.cy),
        *intr.distortion,
        min(intr.max_radius2, 1e30),
        intr.width,
        intr.height,
    )
    return Lens(*(np.float32(v) for v in values))


@numba.njit(**_JIT)
def _touched_blocks(
    z, xs, ys, rot, t, origin, voxel, trunc, stride, nb, mark, stamp
):  # pragma: no cover
    # Marks (mark[b] = stamp) the blocks within trunc of every stride-th depth point.
    h, w = z.shape
    bside = voxel * BLOCK
    for r in range(0, h, stride):
        for c in range(0, w, stride):
            d = z[r, c]
            if not d > 0:
                continue
            px, py = xs[r, c] * d, ys[r, c] * d
            for s in (-trunc, 0.0, trunc):
                scale = (d + s) / d
                q0 = px * scale
                q1 = py * scale
                q2 = d + s
                wx = rot[0, 0] * q0 + rot[0, 1] * q1 + rot[0, 2] * q2 + t[0]
                wy = rot[1, 0] * q0 + rot[1, 1] * q1 + rot[1, 2] * q2 + t[1]
                wz = rot[2, 0] * q0 + rot[2, 1] * q1 + rot[2, 2] * q2 + t[2]
                bi = int(np.floor((wx - origin[0] + 0.5 * voxel) / bside))
                bj = int(np.floor((wy - origin[1] + 0.5 * voxel) / bside))
                bk = int(np.floor((wz - origin[2] + 0.5 * voxel) / bside))
                if 0 <= bi < nb[0] and 0 <= bj < nb[1] and 0 <= bk < nb[2]:
                    mark[bi, bj, bk] = stamp


@numba.njit(parallel=True, **_JIT)
def _integrate_blocks(
    blocks, z, lens, rot_cw, t_cw, origin, voxel, trunc, tsdf, weight
):  # pragma: no cover
    # Projective TSDF update of every voxel of the listed blocks (rot_cw, t_cw: camera from
    # world, float32).
    nx, ny, nz = tsdf.shape
    width = np.int32(lens.width)
    for b in numba.prange(blocks.shape[0]):
        i0, j0, k0 = blocks[b, 0] * BLOCK, blocks[b, 1] * BLOCK, blocks[b, 2] * BLOCK
        for i in range(i0, min(i0 + BLOCK, nx)):
            wx = origin[0] + i * voxel
            for j in range(j0, min(j0 + BLOCK, ny)):
                wy = origin[1] + j * voxel
                for k in range(k0, min(k0 + BLOCK, nz)):
                    wz = origin[2] + k * voxel
                    x = rot_cw[0, 0] * wx + rot_cw[0, 1] * wy + rot_cw[0, 2] * wz + t_cw[0]
                    y = rot_cw[1, 0] * wx + rot_cw[1, 1] * wy + rot_cw[1, 2] * wz + t_cw[1]
                    zc = rot_cw[2, 0] * wx + rot_cw[2, 1] * wy + rot_cw[2, 2] * wz + t_cw[2]
                    if zc <= 0:
                        continue
                    _, _, _, idx = project_point(x, y, zc, lens)
                    if idx < 0:
                        continue
                    d = z[idx // width, idx % width]
                    if not d > 0:
                        continue
                    sdf = d - zc
                    if sdf < -trunc:
                        continue  # far behind the surface: unknown, not free
                    f = min(np.float32(1.0), sdf / trunc)
                    w0 = weight[i, j, k]
                    tsdf[i, j, k] = (tsdf[i, j, k] * w0 + f) / (w0 + 1)
                    weight[i, j, k] = w0 + 1


@dataclass(eq=False)
class Volume:
    """A TSDF voxel grid (module docstring): origin_m (3,) the centre of voxel (0, 0, 0) in
    the grid's frame; voxel_m the voxel side; tsdf and weight (nx, ny, nz) float32; trunc_m
    the truncation distance (default 4 voxels); grid_from_world where the grid lies."""

    origin_m: FloatArray
    voxel_m: float
    tsdf: NDArray[np.float32]
    weight: NDArray[np.float32]
    trunc_m: float
    grid_from_world: RigidTransform = field(
        default_factory=lambda: RigidTransform.identity("grid", "world")
    )

    @classmethod
    def of_points(cls, points_m: FloatArray, voxel_m: float, trunc_voxels: float = 4.0) -> Volume:
        """An empty grid round points (N, 3) world m, turned to their smallest box (trimesh's
        minimum-volume oriented box over their convex hull)."""
        try:
            import trimesh
        except ImportError:
            raise InputError(
                "thermodepth map needs trimesh: pip install 'thermodepth[map]'"
            ) from None
        matrix, _ = trimesh.bounds.oriented_bounds(points_m)
        rot = matrix[:3, :3]
        if np.linalg.det(rot) < 0:  # a mirrored box: turn its last axis round
            rot = rot * np.array([[1.0], [1.0], [-1.0]])
        grid_from_world = RigidTransform(rot, np.zeros(3), "grid", "world")
        local = grid_from_world.apply(points_m)
        return cls.of_bounds(local.min(0), local.max(0), voxel_m, trunc_voxels, grid_from_world)

    @classmethod
    def of_bounds(
        cls,
        lo_m: FloatArray,
        hi_m: FloatArray,
        voxel_m: float,
        trunc_voxels: float = 4.0,
        grid_from_world: RigidTransform | None = None,
    ) -> Volume:
        """An empty grid covering the box lo_m .. hi_m (grid frame, m; the world's unless
        ``grid_from_world`` is given) with a margin of the truncation distance; InputError
        if it would hold more than :data:`MAX_VOXELS`."""
        if not voxel_m > 0:
            raise InputError(f"voxel size {voxel_m} m: must be > 0")
        trunc = trunc_voxels * voxel_m
        lo = np.asarray(lo_m, np.float64) - trunc
        hi = np.asarray(hi_m, np.float64) + trunc
        shape = tuple(int(n) for n in np.ceil((hi - lo) / voxel_m).astype(int) + 1)
        count = int(np.prod(shape, dtype=np.int64))
        if count > MAX_VOXELS:
            size = " x ".join(f"{s:.1f}" for s in hi - lo)
            raise InputError(
                f"a {size} m box at {voxel_m * 100:g} cm voxels is {count / 1e6:.0f} M voxels "
                f"(over {MAX_VOXELS / 1e6:.0f} M): give a larger voxel or a shorter max range"
            )
        return cls(
            lo,
            float(voxel_m),
            np.ones(shape, np.float32),
            np.zeros(shape, np.float32),
            float(trunc),
            grid_from_world or RigidTransform.identity("grid", "world"),
        )

    @property
    def shape(self) -> tuple[int, int, int]:
        nx, ny, nz = self.tsdf.shape
        return nx, ny, nz

    def integrate(
        self,
        depth_m: NDArray[np.float32],
        intr: Intrinsics,
        world_from_depth: RigidTransform,
        rays: tuple[FloatArray, FloatArray],
        stride: int = 4,
    ) -> int:
        """Fuse one depth image (H, W) metres (NaN or 0: none) seen from ``world_from_depth``;
        ``rays`` are the depth camera's :func:`~thermodepth.camera.pixel_rays`; every
        ``stride``-th pixel each way finds the blocks to visit. Returns how many blocks."""
        nb = np.array([-(-n // BLOCK) for n in self.shape], np.int64)
        mark = np.zeros(tuple(nb), np.uint8)
        z = np.nan_to_num(depth_m, nan=0.0).astype(np.float32, copy=False)
        grid_from_depth = self.grid_from_world @ world_from_depth
        rot = grid_from_depth.rotation
        t = grid_from_depth.translation_m
        _touched_blocks(
            z, rays[0], rays[1], rot, t, self.origin_m, self.voxel_m, self.trunc_m, stride, nb,
            mark, np.uint8(1),
        )  # fmt: skip
        blocks = np.argwhere(mark).astype(np.int64)
        inv = grid_from_depth.inverse()
        _integrate_blocks(
            blocks,
            z,
            lens_for(intr),
            inv.rotation.astype(np.float32),
            inv.translation_m.astype(np.float32),
            self.origin_m.astype(np.float32),
            np.float32(self.voxel_m),
            np.float32(self.trunc_m),
            self.tsdf,
            self.weight,
        )
        return len(blocks)

    def mesh(
        self, min_weight: float = 1.0, min_part_voxels: int = 25
    ) -> tuple[FloatArray, NDArray[np.int64], FloatArray]:
        """The surface: vertices (V, 3) world m, triangles (F, 3), unit normals (V, 3) pointing
        out of the surface (towards where the cameras were). Marching cubes on the cubes whose
        eight corners have at least ``min_weight``; parts of the mesh (connected by their
        vertices) smaller than ``min_part_voxels`` voxel faces are left out (the depth's noise
        just behind a surface); empty arrays if there is no surface."""
        try:
            from skimage.measure import marching_cubes
        except ImportError:
            raise InputError(
                "thermodepth map needs scikit-image: pip install 'thermodepth[map]'"
            ) from None
        seen = self.weight >= min_weight
        # a cube (i, j, k) spans voxels i..i+1: all eight of its corners seen
        cube = seen[:-1, :-1, :-1].copy()
        for di, dj, dk in np.ndindex(2, 2, 2):
            cube &= seen[di : di + cube.shape[0], dj : dj + cube.shape[1], dk : dk + cube.shape[2]]
        # scikit-image reads mask[i, j, k] for the cube ending at voxel (i, j, k)
        mask = np.zeros_like(seen)
        mask[1:, 1:, 1:] = cube
        if not cube.any() or self.tsdf[seen].min() >= 0 or self.tsdf[seen].max() <= 0:
            return np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros((0, 3))
        verts, faces, normals, _ = marching_cubes(
            self.tsdf, 0.0, spacing=(self.voxel_m,) * 3, mask=mask, gradient_direction="descent"
        )
        # a voxel's face of surface is about two triangles
        verts, faces, normals = _without_small_parts(verts, faces, normals, 2 * min_part_voxels)
        # scikit-image's normals point down the gradient's opposite here (into the surface,
        # towards negative tsdf) while its "descent" winding faces the free side: flip them
        world_from_grid = self.grid_from_world.inverse()
        return (
            world_from_grid.apply(verts.astype(np.float64) + self.origin_m),
            faces.astype(np.int64),
            -normals.astype(np.float64) @ world_from_grid.rotation.T,
        )


def _without_small_parts(
    verts: FloatArray, faces: NDArray[np.int64], normals: FloatArray, min_faces: int
) -> tuple[FloatArray, NDArray[np.int64], FloatArray]:
    """The mesh without its connected parts of fewer than ``min_faces`` triangles, vertices
    renumbered."""
    n = len(verts)
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    part = labels[faces[:, 0]]
    keep_face = np.bincount(part)[part] >= min_faces
    keep_vert = np.zeros(n, bool)
    keep_vert[faces[keep_face].ravel()] = True
    new_index = np.cumsum(keep_vert) - 1
    return verts[keep_vert], new_index[faces[keep_face]], normals[keep_vert]
