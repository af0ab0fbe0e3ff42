"""The ground truth of a simulated walk, stored in its recording (zarr group ``truth``) so
one file carries it: the scene's rects and their mesh, the true trajectory, the hot spots,
and how many frames saw each point of the surfaces.

Layout (all SI: metres, kelvin, seconds)::

    truth/                 attributes: scene, ambient_temp_k, relative_humidity, rect_names,
                           hotspots [{name, center_m, size_m, temp_c}], seen_spacing_m,
                           seen_step, seen_range_m
      rects/center_m    (R, 3)  float64   a rect's centre
      rects/axis_u      (R, 3)  float64   its unit in-plane axes (normal = u x v)
      rects/axis_v      (R, 3)  float64
      rects/half_m      (R, 2)  float64   half sizes along u and v
      rects/temp_k      (R,)    float64   temperature
      rects/emissivity  (R,)    float64   normal emissivity
      mesh/vertices_m   (4R, 3) float64   two triangles per rect
      mesh/faces        (2R, 3) int64
      mesh/temp_k       (2R,)   float64   per face
      trajectory        (N, 8)  float64   TUM rows (t tx ty tz qx qy qz qw, world_from_depth)
                                          at every depth frame's time
      seen_depth        (M,)    int32     per point of surface_samples(seen_spacing_m): how
      seen_thermal      (M,)    int32     many depth / thermal frames (one in seen_step,
                                          thermal ones out of FFC) saw it

A frame "sees" a point when it projects inside the image, lies within the depth camera's
range (its depth Z, from the depth camera at the frame's time) and the line of sight from
that camera to it crosses no rect (:func:`~.raycast.blocked`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numba
import numpy as np
import zarr
from numpy.typing import ArrayLike, NDArray

from ..camera import Intrinsics, RigidTransform, corner_rays
from ..errors import InputError
from ..progress import Progress
from ..trajectory import Trajectory
from .raycast import blocked
from .scene import RectArrays, Scene

FloatArray = NDArray[np.float64]

TRUTH_GROUP = "truth"
_CHUNK = 8192  # points per block in the point-to-rect work: (chunk, R) arrays stay small


@dataclass(frozen=True)
class Hotspot:
    """A part that stands out thermally: its name, the centre (3,) and size (3,) of its
    axis-aligned bounds in the world (m), and its temperature (C)."""

    name: str
    center_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    temp_c: float


# -- pure array functions ------------------------------------------------------------------


def rect_mesh(rects: RectArrays) -> tuple[FloatArray, NDArray[np.int64]]:
    """Two triangles per rect: vertices (4R, 3) m (corners -u-v, +u-v, +u+v, -u+v) and faces
    (2R, 3) vertex indices, wound counter-clockwise about the rect's normal u x v; face f
    belongs to rect f // 2."""
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64)
    s = corners[None, :, 0] * rects.half_m[:, None, 0]
    q = corners[None, :, 1] * rects.half_m[:, None, 1]
    vertices = (
        rects.center_m[:, None]
        + s[..., None] * rects.axis_u[:, None]
        + q[..., None] * rects.axis_v[:, None]
    )
    base = 4 * np.arange(len(rects.center_m))[:, None, None]
    faces = base + np.array([[0, 1, 2], [0, 2, 3]])[None]
    return vertices.reshape(-1, 3), faces.reshape(-1, 3).astype(np.int64)


def surface_samples(rects: RectArrays, spacing_m: float) -> tuple[FloatArray, NDArray[np.int64]]:
    """A regular grid over every rect: points (M, 3) m at the centres of cells at most
    ``spacing_m`` on a side (at least one per rect; none on an edge) and the rect of each
    (M,)."""
    points, owner = [], []
    for i, (hu, hv) in enumerate(rects.half_m):
        nu, nv = max(1, int(np.ceil(2 * hu / spacing_m))), max(1, int(np.ceil(2 * hv / spacing_m)))
        s = (np.arange(nu) + 0.5) * (2 * hu / nu) - hu
        q = (np.arange(nv) + 0.5) * (2 * hv / nv) - hv
        ss, qq = (a.ravel() for a in np.meshgrid(s, q, indexing="ij"))
        idx = np.full(ss.size, i, np.int64)
        points.append(rects.points_m(idx, ss, qq))
        owner.append(idx)
    return np.concatenate(points or [np.empty((0, 3))]), np.concatenate(
        owner or [np.empty(0, np.int64)]
    )


def nearest_rect(rects: RectArrays, points_m: ArrayLike) -> tuple[FloatArray, NDArray[np.int64]]:
    """The exact distance (N,) m from each point (N, 3) to the nearest rect, and that rect
    (N,); in blocks of points, so millions are fine. A point's distance to a rect is that to
    its nearest point: the in-plane coordinates clamped to the half sizes, plus the offset
    along the normal."""
    p = np.asarray(points_m, np.float64).reshape(-1, 3)
    c_u = np.einsum("ij,ij->i", rects.axis_u, rects.center_m)
    c_v = np.einsum("ij,ij->i", rects.axis_v, rects.center_m)
    c_n = np.einsum("ij,ij->i", rects.normal, rects.center_m)
    hu, hv = rects.half_m[:, 0], rects.half_m[:, 1]
    dist = np.empty(len(p))
    which = np.empty(len(p), np.int64)
    for a in range(0, len(p), _CHUNK):
        block = p[a : a + _CHUNK]
        s = block @ rects.axis_u.T - c_u  # (n, R) in-plane coordinates
        q = block @ rects.axis_v.T - c_v
        h = block @ rects.normal.T - c_n
        d2 = np.square(s - np.clip(s, -hu, hu)) + np.square(q - np.clip(q, -hv, hv)) + np.square(h)
        which[a : a + _CHUNK] = np.argmin(d2, axis=1)
        dist[a : a + _CHUNK] = np.sqrt(np.take_along_axis(d2, which[a : a + _CHUNK, None], 1)[:, 0])
    return dist, which


@numba.njit(parallel=True, cache=True)
def _candidates(points, cam, depth, z_range, xy_box, out_cam, out):  # pragma: no cover - JIT
    # points a view may see: depth Z within range, in front of the camera and inside a box
    # of its normalised coordinates that holds its image (the exact test follows)
    for i in numba.prange(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        zd = depth[2, 0] * x + depth[2, 1] * y + depth[2, 2] * z + depth[2, 3]
        out[i] = False
        if zd < z_range[0] or zd > z_range[1]:
            continue
        for k in range(3):
            out_cam[i, k] = cam[k, 0] * x + cam[k, 1] * y + cam[k, 2] * z + cam[k, 3]
        zc = out_cam[i, 2]
        if zc <= 0.0:
            continue
        xn, yn = out_cam[i, 0] / zc, out_cam[i, 1] / zc
        out[i] = xy_box[0] <= xn <= xy_box[1] and xy_box[2] <= yn <= xy_box[3]


def count_views(
    scene: Scene,
    points_m: FloatArray,
    views: Iterable[tuple[RigidTransform, RigidTransform]],
    intrinsics: Intrinsics,
    range_m: tuple[float, float],
    progress: Progress | None = None,
) -> NDArray[np.int32]:
    """How many of ``views`` see each point (M, 3) of the world (M,).

    A view is (camera_from_world, depth_from_world) at one frame: the point must project
    inside the camera's image (``intrinsics``, distortion included), have its depth Z in the
    depth camera within ``range_m`` (min, max), and be in the camera's line of sight
    (:func:`~.raycast.blocked` against every rect that reaches into the image).
    """
    points = np.ascontiguousarray(points_m, np.float64)
    counts = np.zeros(len(points), np.int32)
    cam = np.empty_like(points)
    near = np.empty(len(points), np.bool_)
    x, y = corner_rays(intrinsics)
    pad = 0.05 * (x.max() - x.min())  # the corners' box, with room for the distortion
    xy_box = np.array([x.min() - pad, x.max() + pad, y.min() - pad, y.max() + pad])
    for camera_from_world, depth_from_world in views:
        _candidates(
            points,
            camera_from_world.matrix,
            depth_from_world.matrix,
            np.asarray(range_m, np.float64),
            xy_box,
            cam,
            near,
        )
        idx = np.flatnonzero(near)
        inside = intrinsics.contains(intrinsics.project(cam[idx]))
        idx = idx[inside]
        hidden = blocked(scene, camera_from_world, cam[idx], in_image=intrinsics)
        counts[idx[~hidden]] += 1
        if progress:
            progress(1)
    return counts


# -- the truth of a walk ---------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class WalkTruth:
    """The truth of a simulated walk (module docstring), read from its recording.

    scene: the scene's name; rect_names (R,); rects: centre, axes, half sizes (R, ...) m;
    temp_k, emissivity (R,); vertices_m (V, 3), faces (F, 3), face_temp_k (F,): the mesh;
    trajectory: ``world_from_depth`` at every depth frame's time; hotspots; ambient_temp_k,
    relative_humidity: the air; seen_spacing_m, seen_step, seen_depth, seen_thermal (M,):
    the view counts of :meth:`seen_samples`' points.
    """

    scene: str
    rect_names: tuple[str, ...]
    rects: RectArrays
    temp_k: FloatArray
    emissivity: FloatArray
    vertices_m: FloatArray
    faces: NDArray[np.int64]
    face_temp_k: FloatArray
    trajectory: Trajectory
    hotspots: tuple[Hotspot, ...]
    ambient_temp_k: float
    relative_humidity: float
    seen_spacing_m: float
    seen_step: int
    seen_range_m: tuple[float, float]
    seen_depth: NDArray[np.int32]
    seen_thermal: NDArray[np.int32]

    def nearest(self, points_m: ArrayLike) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
        """For points (N, 3) m: the exact distance (N,) m to the nearest rect, its
        temperature (N,) K and its index (N,) (:func:`nearest_rect`)."""
        dist, which = nearest_rect(self.rects, points_m)
        return dist, self.temp_k[which], which

    def sample_surface(self, spacing_m: float) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
        """Points (M, 3) m on a regular grid of about ``spacing_m`` over every rect
        (:func:`surface_samples`), their temperature (M,) K and rect (M,)."""
        points, which = surface_samples(self.rects, spacing_m)
        return points, self.temp_k[which], which

    def seen_samples(self) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
        """The points the view counts ``seen_depth`` and ``seen_thermal`` are of:
        :meth:`sample_surface` at ``seen_spacing_m``."""
        return self.sample_surface(self.seen_spacing_m)


def write_walk_truth(
    root: zarr.Group,
    scene_name: str,
    scene: Scene,
    trajectory: Trajectory,
    hotspots: Sequence[Hotspot],
    seen: dict[str, Any],
) -> None:
    """Store the truth of a walk as the group ``truth`` of the recording ``root`` (module
    docstring); ``seen``: seen_spacing_m, seen_step, seen_range_m and the seen_depth and
    seen_thermal counts."""
    g = root.require_group(TRUTH_GROUP)
    rects = scene.geometry
    temp = np.array([r.material.temp_k for r in scene.rects], np.float64)
    vertices, faces = rect_mesh(rects)
    arrays = {
        "rects/center_m": rects.center_m,
        "rects/axis_u": rects.axis_u,
        "rects/axis_v": rects.axis_v,
        "rects/half_m": rects.half_m,
        "rects/temp_k": temp,
        "rects/emissivity": np.array([r.material.emissivity for r in scene.rects], np.float64),
        "mesh/vertices_m": vertices,
        "mesh/faces": faces,
        "mesh/temp_k": np.repeat(temp, 2),
        "trajectory": trajectory.tum_rows(),
        "seen_depth": np.asarray(seen["seen_depth"], np.int32),
        "seen_thermal": np.asarray(seen["seen_thermal"], np.int32),
    }
    for name, data in arrays.items():
        g.create_array(name, data=np.ascontiguousarray(data))
    g.attrs.update(
        {
            "scene": scene_name,
            "ambient_temp_k": scene.ambient_temp_k,
            "relative_humidity": scene.relative_humidity,
            "rect_names": [r.name for r in scene.rects],
            "hotspots": [asdict(h) for h in hotspots],
            "seen_spacing_m": float(seen["seen_spacing_m"]),
            "seen_step": int(seen["seen_step"]),
            "seen_range_m": list(seen["seen_range_m"]),
        }
    )


def read_walk_truth(path: str | Path) -> WalkTruth | None:
    """The truth stored in the recording at ``path`` (None when it has none: a recording of
    real cameras, or of another simulation); InputError if it is no recording."""
    from ..io.recording import Recording  # the simulator stands below io

    root = Recording(path).root
    if TRUTH_GROUP not in root:
        return None
    g = root[TRUTH_GROUP]
    assert isinstance(g, zarr.Group)

    def read(name: str) -> NDArray[Any]:
        node = g[name]
        assert isinstance(node, zarr.Array)
        return np.asarray(node[...])

    try:
        a: dict[str, Any] = dict(g.attrs)
        center, u, v = read("rects/center_m"), read("rects/axis_u"), read("rects/axis_v")
        rects = RectArrays(center, u, v, np.cross(u, v), read("rects/half_m"))
        hotspots = tuple(
            Hotspot(str(h["name"]), _xyz(h["center_m"]), _xyz(h["size_m"]), float(h["temp_c"]))
            for h in a["hotspots"]
        )
        return WalkTruth(
            scene=str(a["scene"]),
            rect_names=tuple(a["rect_names"]),
            rects=rects,
            temp_k=read("rects/temp_k"),
            emissivity=read("rects/emissivity"),
            vertices_m=read("mesh/vertices_m"),
            faces=read("mesh/faces"),
            face_temp_k=read("mesh/temp_k"),
            trajectory=Trajectory.of_tum_rows(read("trajectory")),
            hotspots=hotspots,
            ambient_temp_k=float(a["ambient_temp_k"]),
            relative_humidity=float(a["relative_humidity"]),
            seen_spacing_m=float(a["seen_spacing_m"]),
            seen_step=int(a["seen_step"]),
            seen_range_m=(float(a["seen_range_m"][0]), float(a["seen_range_m"][1])),
            seen_depth=read("seen_depth"),
            seen_thermal=read("seen_thermal"),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{path}: the walk's truth is incomplete ({exc})") from None


def _xyz(values: Sequence[float]) -> tuple[float, float, float]:
    x, y, z = (float(v) for v in values)
    return x, y, z
