"""Pictures of the model without a screen: its triangles rasterised with a z-buffer from a
virtual pinhole camera, coloured by the vertices' colours and shaded by the angle to a light
at the camera (Lambert), on a grey background; triangles that face away are not drawn."""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from ..camera import RigidTransform

FloatArray = NDArray[np.float64]
BACKGROUND = np.array([40, 40, 46], np.uint8)


@numba.njit(cache=True)
def _raster(pu, pv, pz, shade, colours, tris, zbuf, image):  # pragma: no cover - JIT
    h, w = zbuf.shape
    for f in range(tris.shape[0]):
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        if pz[a] <= 0 or pz[b] <= 0 or pz[c] <= 0:
            continue
        x0, y0, x1, y1, x2, y2 = pu[a], pv[a], pu[b], pv[b], pu[c], pv[c]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if area == 0:
            continue
        c0 = max(int(np.floor(min(x0, x1, x2))), 0)
        c1 = min(int(np.ceil(max(x0, x1, x2))), w - 1)
        r0 = max(int(np.floor(min(y0, y1, y2))), 0)
        r1 = min(int(np.ceil(max(y0, y1, y2))), h - 1)
        for r in range(r0, r1 + 1):
            for col in range(c0, c1 + 1):
                # barycentric weights of the pixel centre
                l1 = ((col - x0) * (y2 - y0) - (x2 - x0) * (r - y0)) / area
                l2 = ((x1 - x0) * (r - y0) - (col - x0) * (y1 - y0)) / area
                l0 = 1.0 - l1 - l2
                if l0 < 0 or l1 < 0 or l2 < 0:
                    continue
                z = l0 * pz[a] + l1 * pz[b] + l2 * pz[c]
                if z >= zbuf[r, col]:
                    continue
                zbuf[r, col] = z
                s = l0 * shade[a] + l1 * shade[b] + l2 * shade[c]
                for k in range(3):
                    v = l0 * colours[a, k] + l1 * colours[b, k] + l2 * colours[c, k]
                    image[r, col, k] = min(max(v * s, 0.0), 255.0)


def look_at(eye_m: FloatArray, target_m: FloatArray, up: FloatArray) -> RigidTransform:
    """``camera_from_world`` of a camera at ``eye_m`` looking at ``target_m`` (z forward,
    y down in the picture, ``up`` the world's up)."""
    z = np.asarray(target_m, float) - np.asarray(eye_m, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, -np.asarray(up, float))
    if np.linalg.norm(x) < 1e-9:  # looking along up: any side will do
        x = np.cross(z, np.array([1.0, 0.0, 0.0]))
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    rot = np.stack([x, y, z])  # rows: the camera's axes in the world
    return RigidTransform(rot, -rot @ np.asarray(eye_m, float), "view", "world")


def render(
    vertices: FloatArray,
    triangles: NDArray[np.int64],
    normals: FloatArray,
    colours: NDArray[np.uint8],
    view_from_world: RigidTransform,
    size: tuple[int, int] = (800, 600),
    hfov_deg: float = 50.0,
) -> NDArray[np.uint8]:
    """An RGB picture (h, w, 3) of the mesh (vertices, triangles, unit normals, RGB colours
    per vertex) from a pinhole camera ``view_from_world`` of ``hfov_deg`` and ``size``
    (width, height) pixels."""
    w, h = size
    f = (w / 2) / np.tan(np.radians(hfov_deg) / 2)
    p = view_from_world.apply(vertices)
    z = p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        pu = f * p[:, 0] / z + (w - 1) / 2
        pv = f * p[:, 1] / z + (h - 1) / 2
    n_view = normals @ view_from_world.rotation.T
    ray = p / np.maximum(np.linalg.norm(p, axis=1, keepdims=True), 1e-12)
    shade = 0.35 + 0.65 * np.abs(np.einsum("ij,ij->i", n_view, ray))
    # only the triangles that face the camera: from outside a room, its far walls' insides
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    eye = view_from_world.inverse().translation_m
    facing = np.einsum("ij,ij->i", np.cross(b - a, c - a), eye - a) > 0
    zbuf = np.full((h, w), np.inf)
    image = np.empty((h, w, 3), np.float64)
    image[:] = BACKGROUND
    _raster(pu, pv, z, shade, colours.astype(np.float64), triangles[facing], zbuf, image)
    return image.astype(np.uint8)


def orbit_views(
    vertices: FloatArray, up: FloatArray, n: int = 4, hfov_deg: float = 50.0, margin: float = 1.05
) -> list[tuple[str, RigidTransform]]:
    """``n`` cameras around the centre of ``vertices`` (what the pictures are of), 30 degrees
    above it, far enough for them all to fit in ``hfov_deg`` with ``margin`` (1: touching);
    named by their bearing."""
    lo, hi = np.percentile(vertices, [1, 99], axis=0)
    centre = (lo + hi) / 2
    radius = np.linalg.norm(hi - lo) / 2
    dist = radius / np.sin(np.radians(hfov_deg) / 2) * margin
    up = np.asarray(up, float) / np.linalg.norm(up)
    side = np.cross(up, [1.0, 0.0, 0.0])
    if np.linalg.norm(side) < 1e-6:
        side = np.cross(up, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    other = np.cross(up, side)
    views = []
    for k in range(n):
        a = 2 * np.pi * k / n
        horizontal = np.cos(a) * side + np.sin(a) * other
        eye = centre + dist * (np.cos(np.radians(30)) * horizontal + np.sin(np.radians(30)) * up)
        views.append((f"view {360 * k // n} deg", look_at(eye, centre, up)))
    return views
