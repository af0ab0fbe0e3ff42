"""Temperature on the model's surface, fused from every thermal view with the physics that
decide whether a view can be trusted.

A thermal view is one thermal frame at its own pose (the rig's pose at the thermal frame's
time, so a moving rig's two cameras are each where they were when they exposed). For each
vertex of the mesh and each view that sees it (inside the image, not hidden behind a nearer
part of the mesh: the view's z-buffer of the mesh itself), one sample: the view's temperature
at the vertex's nearest pixel, made with that view's own distance to the surface (the air)
and corrected for the emissivity at the viewing angle (:func:`angle_corrected`). Its weight
is the product of

- the viewing angle: none beyond ``max_angle_deg`` (60 by default; emissivity falls and a
  pixel spreads over the surface beyond it), else cos(angle);
- the footprint: a pixel's size on the surface, range / (f cos angle); weight
  (1 cm / footprint)^2, so near, head-on views count most (a spot that covers few pixels
  reads low: the 3x3 rule, Infrared Training Center); and only the views whose footprint
  is within ``footprint_ratio`` (2) of the nearest view's: many distant views of a small
  hot part would otherwise outvote the few that resolve it;
- the distance from depth edges in the view: none within ``edge_px[0]`` pixels, full from
  ``edge_px[1]`` (a pixel on an edge mixes the foreground and the background, and the optics
  blur spreads it);
- the view's own weight: none while the shutter is closed, none when the rig turned so fast
  that the image smears over more than ``max_smear_px`` (the bolometer's thermal time
  constant times the angular speed), falling linearly from ``smear_px[0]``.

The samples of a vertex are reduced by a method of :data:`FUSION_METHODS` (weighted median
by default: a view that sees a reflection of something hot is one outlier among many); the
spread kept is the weighted median absolute deviation (scaled to a standard deviation), the
best view's temperature is that of the smallest footprint. ``plain`` is the baseline that the
literature's thermal mappers use: the unweighted mean of every view that sees the vertex,
uncorrected.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import cv2
import numba
import numpy as np
from numpy.typing import NDArray

from ..camera import Intrinsics, RigidTransform
from ..radiometry import ZERO_C_IN_K, band_radiance, fresnel_emissivity
from ..registration.kernels import Lens, project_point
from .volume import lens_for

FloatArray = NDArray[np.float64]
# fastmath without "nnan" and "ninf": the kernels test for NaN (no temperature) and inf (no
# surface), which those flags would let LLVM fold away
_JIT: dict[str, Any] = {
    "cache": True,
    "fastmath": {"nsz", "arcp", "contract", "afn"},
    "error_model": "numpy",
}

FUSION_METHODS: dict[str, int] = {"median": 0, "trimmed": 1, "mean": 2, "plain": 3}
"""How a vertex's samples become its temperature: the weighted median (default), the weighted
mean of the middle half (``trimmed``), the weighted mean, or ``plain``: the unweighted mean of
every view that sees it, no angle correction (the baseline)."""


@dataclass(frozen=True)
class FusionOptions:
    """The weights of the module docstring: max_angle_deg (none beyond), edge_px (none
    within the first, full from the second), smear_px (full up to the first, none from the
    second), thermal_time_constant_s (the bolometer's, for the smear; a Lepton's ~12 ms),
    method (:data:`FUSION_METHODS`), directional (correct each sample for the emissivity at
    its angle, Fresnel; False: the stated emissivity at every angle), footprint_ratio (only
    views whose footprint is within this factor of the nearest view's; inf: all),
    peak_footprint_ratio (the same for a hotspot's peak, :func:`view_peak`)."""

    max_angle_deg: float = 60.0
    edge_px: tuple[float, float] = (1.0, 3.0)
    smear_px: tuple[float, float] = (0.5, 2.0)
    thermal_time_constant_s: float = 0.012
    method: str = "median"
    directional: bool = True
    footprint_ratio: float = 2.0
    peak_footprint_ratio: float = 1.25


@dataclass(frozen=True, eq=False)
class ThermalView:
    """One thermal frame as the fusion takes it: time_s; thermal_from_world at that time;
    temp_c (h, w) its temperatures (NaN: none); z_m (h, w) the mesh's nearest Z in this view
    (inf: none); edge_px (h, w) each pixel's distance to the nearest depth edge, pixels;
    weight (0..1: shutter and motion); smear_px (how far the image smeared); blocks_seen
    (B,): which of the mesh's :class:`VertexBlocks` may be in view (None: all)."""

    time_s: float
    thermal_from_world: RigidTransform
    temp_c: NDArray[np.float32]
    z_m: NDArray[np.float32]
    edge_px: NDArray[np.float32]
    weight: float
    smear_px: float
    blocks_seen: NDArray[np.bool_] | None = None


@dataclass(frozen=True, eq=False)
class VertexBlocks:
    """A mesh's vertices in cubes of ``side_m``, numbered cube by cube, so that a view skips
    the cubes out of its sight without looking at their vertices: start (B + 1,) the first
    vertex of each cube (cube b holds vertices start[b] .. start[b + 1] - 1), block_of (V,)
    each vertex's cube, centre_m (B, 3) and radius_m (B,) a sphere holding each cube's
    vertices (world m)."""

    start: NDArray[np.int64]
    block_of: NDArray[np.int32]
    centre_m: FloatArray
    radius_m: FloatArray

    @staticmethod
    def sort(
        vertices: FloatArray,
        triangles: NDArray[np.int64],
        normals: FloatArray,
        side_m: float = 0.25,
    ) -> tuple[FloatArray, NDArray[np.int64], FloatArray, VertexBlocks]:
        """The mesh with its vertices renumbered cube by cube, and its blocks."""
        cell = np.floor(vertices / side_m).astype(np.int64)
        cell -= cell.min(axis=0) if len(cell) else 0
        span = cell.max(axis=0) + 1 if len(cell) else np.ones(3, np.int64)
        # one integer per cube: a 1-D unique is far faster than numpy's row-wise one
        key = (cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2]
        _, cube = np.unique(key, return_inverse=True)
        order = np.argsort(cube, kind="stable")
        renumber = np.empty_like(order)
        renumber[order] = np.arange(len(order))
        verts, block_of = vertices[order], cube[order].astype(np.int32)
        n = int(block_of.max()) + 1 if len(block_of) else 0
        count = np.bincount(block_of, minlength=n)
        start = np.concatenate([[0], np.cumsum(count)])
        sums = np.stack([np.bincount(block_of, verts[:, k], n) for k in range(3)], axis=1)
        centre: FloatArray = sums / np.maximum(count, 1)[:, None]
        radius = np.zeros(n)
        np.maximum.at(radius, block_of, np.linalg.norm(verts - centre[block_of], axis=1))
        blocks = VertexBlocks(start, block_of, centre, radius)
        return verts, renumber[triangles], normals[order], blocks

    @staticmethod
    def one(n_vertices: int) -> VertexBlocks:
        """All vertices in one block, always looked at."""
        return VertexBlocks(
            np.array([0, n_vertices]), np.zeros(n_vertices, np.int32), np.zeros((1, 3)),
            np.full(1, np.inf),
        )  # fmt: skip

    def in_view(self, camera_from_world: RigidTransform, intr: Intrinsics) -> NDArray[np.bool_]:
        """(B,) whether each cube's sphere may reach into the image (pinhole, with a margin
        for the lens' distortion): in front of the camera and within the image's cone."""
        c = self.centre_m @ camera_from_world.rotation.T + camera_from_world.translation_m
        z, r = c[:, 2], self.radius_m
        zz = np.maximum(z - r, 0.01)
        # the sphere's reach in pixels at its nearest depth, plus 10 % of the image
        reach = r * max(intr.fx, intr.fy) / zz + 0.1 * max(intr.width, intr.height)
        u = intr.fx * c[:, 0] / np.maximum(z, 0.01) + intr.cx
        v = intr.fy * c[:, 1] / np.maximum(z, 0.01) + intr.cy
        inside = (u > -reach) & (u < intr.width + reach) & (v > -reach) & (v < intr.height + reach)
        touching = z - r <= 0.01  # a sphere across the camera's plane: always looked at
        return (z + r > 0.01) & (inside | touching)


def view_weight(in_ffc: bool, smear_px: float, options: FusionOptions) -> float:
    """A view's own weight: 0 with the shutter closed, else 1 up to ``smear_px[0]`` of smear,
    falling linearly to 0 at ``smear_px[1]``."""
    if in_ffc:
        return 0.0
    lo, hi = options.smear_px
    return float(np.clip((hi - smear_px) / (hi - lo), 0.0, 1.0))


def smear_px(angular_speed_deg_s: float, fx_px: float, time_constant_s: float) -> float:
    """How far a bolometer's image smears while the camera turns: the angle turned in one
    thermal time constant, in pixels (fx per radian near the centre)."""
    return float(np.radians(angular_speed_deg_s) * time_constant_s * fx_px)


@numba.njit(parallel=True, **_JIT)
def _zbuffers(verts, start, seen, rots, trans, lens, voxel, out):  # pragma: no cover - JIT
    # Per view (in parallel), the nearest Z of the mesh's vertices per pixel, each a disc
    # about the size of the gap between vertices there (so a surface has no holes that would
    # show what is behind it); only the blocks the view may see.
    width = np.int32(lens.width)
    height = np.int32(lens.height)
    for k in numba.prange(rots.shape[0]):
        rot, t, zbuf = rots[k], trans[k], out[k]
        for b in range(start.shape[0] - 1):
            if not seen[k, b]:
                continue
            for n in range(start[b], start[b + 1]):
                vx, vy, vz = verts[n, 0], verts[n, 1], verts[n, 2]
                x = rot[0, 0] * vx + rot[0, 1] * vy + rot[0, 2] * vz + t[0]
                y = rot[1, 0] * vx + rot[1, 1] * vy + rot[1, 2] * vz + t[1]
                z = rot[2, 0] * vx + rot[2, 1] * vy + rot[2, 2] * vz + t[2]
                if z <= 0.01:
                    continue
                uu, vv, pz, idx = project_point(x, y, z, lens)
                if idx < -1 and not (-8 < uu < width + 8 and -8 < vv < height + 8):
                    continue
                # vertices are about a voxel apart: a disc of 3/4 of that gap covers it
                r = int(0.75 * voxel * lens.fx / pz + 0.5)
                cu = int(np.floor(uu + 0.5))
                cv = int(np.floor(vv + 0.5))
                for dv in range(-r, r + 1):
                    row = cv + dv
                    if row < 0 or row >= height:
                        continue
                    for du in range(-r, r + 1):
                        col = cu + du
                        if 0 <= col < width and pz < zbuf[row, col]:
                            zbuf[row, col] = pz


def render_z(
    vertices: NDArray[np.floating],
    thermal_from_world: list[RigidTransform],
    lens: Lens,
    voxel_m: float,
    blocks: VertexBlocks | None = None,
    seen: NDArray[np.bool_] | None = None,
) -> NDArray[np.float32]:
    """The mesh's nearest Z (m) in a camera at each of its poses (n, h, w), inf where no
    vertex falls; only the vertices of the ``blocks`` each view has ``seen`` (n, B) (None:
    all, in one block)."""
    n = len(thermal_from_world)
    out = np.full((n, int(lens.height), int(lens.width)), np.inf, np.float32)
    if blocks is None or seen is None:
        blocks, seen = VertexBlocks.one(len(vertices)), np.ones((n, 1), np.bool_)
    _zbuffers(
        np.ascontiguousarray(vertices, np.float32),
        blocks.start,
        seen,
        np.array([p.rotation for p in thermal_from_world], np.float32).reshape(n, 3, 3),
        np.array([p.translation_m for p in thermal_from_world], np.float32).reshape(n, 3),
        lens,
        np.float32(voxel_m),
        out,
    )
    return out


def edge_distance_px(z_m: NDArray[np.float32], voxel_m: float) -> NDArray[np.float32]:
    """Each pixel's distance (pixels) to the nearest depth edge: a pixel with no surface, or
    whose Z differs from a 4-neighbour's by more than 3 voxels plus 3 % of its Z."""
    z = np.where(np.isfinite(z_m), z_m, np.float32(1e6))
    jump = np.float32(3 * voxel_m) + np.float32(0.03) * z
    edge = ~np.isfinite(z_m)
    dz_v = np.abs(np.diff(z, axis=0)) > np.minimum(jump[1:], jump[:-1])
    dz_u = np.abs(np.diff(z, axis=1)) > np.minimum(jump[:, 1:], jump[:, :-1])
    edge[1:] |= dz_v
    edge[:-1] |= dz_v
    edge[:, 1:] |= dz_u
    edge[:, :-1] |= dz_u
    return cv2.distanceTransform((~edge).astype(np.uint8), cv2.DIST_L2, 3).astype(np.float32)


def range_of(z_m: NDArray[np.float32], rays: tuple[FloatArray, FloatArray]) -> FloatArray:
    """Range (m) of each pixel from its Z and its undistorted ray (x, y): Z sqrt(1+x^2+y^2);
    NaN where no surface."""
    x, y = rays
    return np.where(np.isfinite(z_m), z_m * np.sqrt(1.0 + x * x + y * y), np.nan)


def make_view(
    time_s: float,
    thermal_from_world: RigidTransform,
    z_m: NDArray[np.float32],
    seen: NDArray[np.bool_],
    thermal: Intrinsics,
    rays: tuple[FloatArray, FloatArray],
    voxel_m: float,
    temperature: Callable[[FloatArray], NDArray[np.float32]],
    in_ffc: bool,
    angular_speed_deg_s: float,
    options: FusionOptions,
) -> ThermalView:
    """A :class:`ThermalView` of the mesh rendered into the thermal camera at its pose
    (``z_m``, :func:`render_z`; the blocks it may see, ``seen``): the frame's temperatures at
    each pixel's range from it (``temperature(range_m)``), its edges and its own weight."""
    smear = smear_px(angular_speed_deg_s, thermal.fx, options.thermal_time_constant_s)
    weight = view_weight(in_ffc, smear, options)
    if in_ffc:  # the shutter's image is no one's temperature, not even the baseline's
        temp = np.full(z_m.shape, np.nan, np.float32)
    else:
        temp = np.asarray(temperature(range_of(z_m, rays)), np.float32)
    edges = edge_distance_px(z_m, voxel_m)
    return ThermalView(time_s, thermal_from_world, temp, z_m, edges, weight, smear, seen)


@numba.njit(**_JIT)
def _weighted_median(values, ws, n, total):  # pragma: no cover - JIT
    # The value at which the sorted samples' weights pass half of their total.
    order = np.argsort(values[:n])
    acc = 0.0
    for i in range(n):
        acc += ws[order[i]]
        if acc >= 0.5 * total:
            return values[order[i]], order
    return values[order[n - 1]], order


@numba.njit(**_JIT)
def _reduce(temps, ws, n, method):  # pragma: no cover - JIT
    # (temperature, spread) of n weighted samples: median, trimmed (middle half) or mean.
    total = 0.0
    for i in range(n):
        total += ws[i]
    med, order = _weighted_median(temps, ws, n, total)
    dev = np.empty(n, np.float32)
    for i in range(n):
        dev[i] = abs(temps[i] - med)
    mad, _ = _weighted_median(dev, ws, n, total)
    spread = 1.4826 * mad
    if method == 0:
        return med, spread
    lo, hi = (0.25 * total, 0.75 * total) if method == 1 else (0.0, total)
    acc = 0.0
    s = 0.0
    sw = 0.0
    for i in range(n):
        w = ws[order[i]]
        part = min(acc + w, hi) - max(acc, lo)  # the share of its weight inside [lo, hi]
        if part > 0:
            s += part * temps[order[i]]
            sw += part
        acc += w
    return (s / sw if sw > 0 else med), spread


@numba.njit(parallel=True, **_JIT)
def _fuse(
    verts, normals, block_of, seen, rots, trans, times, temps, zs, edges, view_w, lens, voxel,
    cos_min, edge_lo, edge_hi, fp_ratio, lut_t, lut_l, lut_cos, lut_eps, eps_n, l_refl, method,
    out,
):  # fmt: skip  # pragma: no cover - JIT
    # out columns: temperature, weight, views, spread, best view's, last seen, plain mean
    nv = rots.shape[0]
    width = np.int32(lens.width)
    ref = np.float32(0.01)  # footprint of weight 1, m
    for v in numba.prange(verts.shape[0]):
        st = np.empty(nv, np.float32)
        sw = np.empty(nv, np.float32)
        sf = np.empty(nv, np.float32)
        n = 0
        plain = 0.0
        n_plain = 0
        best_fp = np.inf
        best = np.nan
        last = -np.inf
        wsum = 0.0
        px, py, pz = verts[v, 0], verts[v, 1], verts[v, 2]
        nx, ny, nz = normals[v, 0], normals[v, 1], normals[v, 2]
        block = block_of[v]
        for k in range(nv):
            if not seen[k, block]:
                continue
            r = rots[k]
            x = r[0, 0] * px + r[0, 1] * py + r[0, 2] * pz + trans[k, 0]
            y = r[1, 0] * px + r[1, 1] * py + r[1, 2] * pz + trans[k, 1]
            z = r[2, 0] * px + r[2, 1] * py + r[2, 2] * pz + trans[k, 2]
            if z <= 0.01:
                continue
            _, _, zc, idx = project_point(x, y, z, lens)
            if idx < 0:
                continue
            row = idx // width
            col = idx % width
            if zc > zs[k, row, col] + 1.5 * voxel + 0.01 * zc:
                continue  # hidden behind a nearer part of the mesh
            t_c = temps[k, row, col]
            if t_c != t_c:  # NaN: no temperature
                continue
            plain += t_c
            n_plain += 1
            wk = view_w[k]
            if wk <= 0:
                continue
            rng = np.sqrt(x * x + y * y + z * z)
            cos = (
                -(
                    (r[0, 0] * nx + r[0, 1] * ny + r[0, 2] * nz) * x
                    + (r[1, 0] * nx + r[1, 1] * ny + r[1, 2] * nz) * y
                    + (r[2, 0] * nx + r[2, 1] * ny + r[2, 2] * nz) * z
                )
                / rng
            )
            if cos < cos_min:
                continue
            we = min(max((edges[k, row, col] - edge_lo) / (edge_hi - edge_lo), 0.0), 1.0)
            if we <= 0:
                continue
            fp = rng / (lens.fx * cos)
            if lut_cos.shape[0] > 0:  # the emissivity at this angle instead of the normal one
                eps = np.interp(cos, lut_cos, lut_eps)
                lt = np.interp(t_c, lut_t, lut_l)
                t_c = np.interp((eps_n * lt + (eps - eps_n) * l_refl) / eps, lut_l, lut_t)
            w = wk * we * cos * (ref / fp) ** 2
            st[n] = t_c
            sw[n] = w
            sf[n] = fp
            n += 1
            last = max(last, times[k])
            if fp < best_fp:
                best_fp = fp
                best = t_c
        # only the views that resolve the surface about as finely as the nearest one: a small
        # hot part reads low in views where it covers few pixels, however many they are
        kept = 0
        for i in range(n):
            if sf[i] <= fp_ratio * best_fp:
                st[kept] = st[i]
                sw[kept] = sw[i]
                wsum += sw[i]
                kept += 1
        n = kept
        if method == 3:
            temp = plain / n_plain if n_plain > 0 else np.nan
            spread = np.nan
        elif n > 0:
            temp, spread = _reduce(st, sw, n, method)
        else:
            temp, spread = np.nan, np.nan
        out[v, 0] = temp
        out[v, 1] = wsum
        out[v, 2] = n
        out[v, 3] = spread
        out[v, 4] = best
        out[v, 5] = last if n > 0 else np.nan
        out[v, 6] = plain / n_plain if n_plain > 0 else np.nan


@dataclass(frozen=True, eq=False)
class SurfaceTemperature:
    """Per vertex (V,): temp_c (fused, NaN: no trusted view), weight (sum of the samples'
    weights), views (trusted samples), spread_c (weighted MAD scaled to an SD), best_c (the
    smallest footprint's), last_seen_s, plain_c (the baseline: unweighted mean of every view
    that saw it, uncorrected)."""

    temp_c: FloatArray
    weight: FloatArray
    views: NDArray[np.int32]
    spread_c: FloatArray
    best_c: FloatArray
    last_seen_s: FloatArray
    plain_c: FloatArray


def fuse(
    vertices: FloatArray,
    normals: FloatArray,
    views: list[ThermalView],
    thermal: Intrinsics,
    voxel_m: float,
    emissivity: float,
    reflected_temp_c: float,
    options: FusionOptions = FusionOptions(),
    blocks: VertexBlocks | None = None,
) -> SurfaceTemperature:
    """Fuse ``views`` onto the mesh's ``vertices`` (V, 3) with their unit ``normals`` (V, 3),
    world m (module docstring); ``emissivity`` and ``reflected_temp_c`` are those the views'
    temperatures were made with (the normal emissivity of the surface); ``blocks``: the
    vertices' blocks the views' ``blocks_seen`` refer to (None: every view sees all)."""
    if options.method not in FUSION_METHODS:
        raise ValueError(f"fusion method {options.method!r}: choose from {list(FUSION_METHODS)}")
    n_v = len(vertices)
    out = np.full((n_v, 7), np.nan)
    if views and n_v:
        lut_c, lut_l = _radiance_table()
        if options.directional:
            lut_cos = np.linspace(0.0, 1.0, 1001)
            lut_eps = fresnel_emissivity(lut_cos, emissivity)
        else:
            lut_cos = lut_eps = np.zeros(0)
        l_refl = float(band_radiance(np.array([reflected_temp_c + ZERO_C_IN_K]))[0])
        _fuse(
            np.ascontiguousarray(vertices, np.float32),
            np.ascontiguousarray(normals, np.float32),
            *_seen_by_views(n_v, views, blocks),
            np.array([v.thermal_from_world.rotation for v in views], np.float32),
            np.array([v.thermal_from_world.translation_m for v in views], np.float32),
            np.array([v.time_s for v in views], np.float64),
            np.stack([v.temp_c for v in views]),
            np.stack([v.z_m for v in views]),
            np.stack([v.edge_px for v in views]),
            np.array([v.weight for v in views], np.float32),
            lens_for(thermal),
            np.float32(voxel_m),
            np.float32(np.cos(np.radians(options.max_angle_deg))),
            np.float32(options.edge_px[0]),
            np.float32(options.edge_px[1]),
            np.float32(options.footprint_ratio),
            lut_c,
            lut_l,
            lut_cos,
            np.asarray(lut_eps, np.float64),
            float(emissivity),
            l_refl,
            FUSION_METHODS[options.method],
            out,
        )
    return SurfaceTemperature(
        out[:, 0], out[:, 1], np.nan_to_num(out[:, 2]).astype(np.int32), *out[:, 3:].T
    )


def _seen_by_views(
    n_vertices: int, views: list[ThermalView], blocks: VertexBlocks | None
) -> tuple[NDArray[np.int32], NDArray[np.bool_]]:
    """Each vertex's block, and (n_views, B) which blocks each view may see."""
    masks = [v.blocks_seen for v in views]
    if blocks is None or any(m is None for m in masks):
        return VertexBlocks.one(n_vertices).block_of, np.ones((len(views), 1), np.bool_)
    return blocks.block_of, np.stack([m for m in masks if m is not None])


@lru_cache(maxsize=1)
def _radiance_table() -> tuple[FloatArray, FloatArray]:
    """Band radiance (8-14 um) on a grid of temperatures, -70 .. 900 C in 0.05 C: for L(T)
    and its inverse by interpolation (error below 1e-3 C)."""
    grid_c = np.linspace(-70.0, 900.0, 19401)
    return grid_c, band_radiance(grid_c + ZERO_C_IN_K)


def angle_corrected(
    temp_c: FloatArray, cos_angle: FloatArray, emissivity: float, reflected_temp_c: float
) -> FloatArray:
    """Temperatures (C) read with the normal ``emissivity`` at viewing angles of cosine
    ``cos_angle``, corrected to the emissivity at that angle (Fresnel,
    :func:`~thermodepth.radiometry.fresnel_emissivity`), on band radiance:
    L(T) = (eps_n L(T_read) + (eps(angle) - eps_n) L(T_refl)) / eps(angle). The kernel of
    :func:`fuse` does the same with tables."""
    grid_c, lut = _radiance_table()
    eps = fresnel_emissivity(cos_angle, emissivity)
    l_refl = float(band_radiance(np.array([reflected_temp_c + ZERO_C_IN_K]))[0])
    radiance = (emissivity * np.interp(temp_c, grid_c, lut) + (eps - emissivity) * l_refl) / eps
    return np.asarray(np.interp(radiance, lut, grid_c))


def view_peak(
    points_m: FloatArray,
    normal: FloatArray,
    views: list[ThermalView],
    thermal: Intrinsics,
    voxel_m: float,
    emissivity: float,
    reflected_temp_c: float,
    options: FusionOptions = FusionOptions(),
) -> tuple[float, int]:
    """The peak temperature (C) of a small hot part of the surface (its vertices ``points_m``
    (P, 3) world m, its unit ``normal``) as a thermographer reads a spot: in each trusted view
    that sees it (by the angle, the shutter, the motion, as :func:`fuse`), the hottest pixel
    of its outline and the pixels next to it; then the median over the views whose footprint
    is within ``peak_footprint_ratio`` of the nearest view's (a spot covering few pixels
    reads low: those views are set aside however many). Returns the peak and how many views gave it
    (NaN, 0: none)."""
    centre = points_m.mean(axis=0)
    reads, footprints, cosines = [], [], []
    cos_min = np.cos(np.radians(options.max_angle_deg))
    for view in views:
        if view.weight <= 0:
            continue
        rot, t = view.thermal_from_world.rotation, view.thermal_from_world.translation_m
        c = rot @ centre + t
        if c[2] <= 0.01:
            continue
        rng = float(np.linalg.norm(c))
        cos = float(-(rot @ normal) @ c / rng)
        if cos < cos_min:
            continue
        p = points_m @ rot.T + t
        px = thermal.project(p)
        ok = np.all(np.isfinite(px), axis=1) & (p[:, 2] > 0.01)
        col = np.floor(px[ok, 0] + 0.5).astype(int)
        row = np.floor(px[ok, 1] + 0.5).astype(int)
        inside = (col >= 0) & (col < thermal.width) & (row >= 0) & (row < thermal.height)
        col, row, z = col[inside], row[inside], p[ok][inside, 2]
        seen = z <= view.z_m[row, col] + 1.5 * voxel_m + 0.01 * z
        if not seen.any():
            continue
        h, w = view.temp_c.shape
        best = -np.inf
        for dr in (-1, 0, 1):  # the outline and the pixels next to it
            for dc in (-1, 0, 1):
                r = np.clip(row[seen] + dr, 0, h - 1)
                cc = np.clip(col[seen] + dc, 0, w - 1)
                best = max(best, float(np.nanmax(view.temp_c[r, cc], initial=-np.inf)))
        if np.isfinite(best):
            reads.append(best)
            footprints.append(rng / (thermal.fx * cos))
            cosines.append(cos)
    if not reads:
        return float("nan"), 0
    fp = np.array(footprints)
    near = fp <= options.peak_footprint_ratio * fp.min()
    temps = np.array(reads)[near]
    if options.directional:
        temps = angle_corrected(temps, np.array(cosines)[near], emissivity, reflected_temp_c)
    return float(np.median(temps)), int(near.sum())
