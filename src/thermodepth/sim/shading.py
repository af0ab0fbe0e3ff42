"""What a camera sees along its rays: the material each ray meets (a rect's, or its pattern's
second one), the near-IR albedo and temperature there, the in-band radiance that reaches the
lens, and whole renders whose pixels are the mean of their sub-rays (the pixel footprint).

The per-ray work runs in numba kernels (:mod:`.kernels`) over a table of the scene's
surfaces built once per scene (:class:`SurfaceTable`); the renders (:func:`render_aperture`,
:func:`render_ir_albedo`) cast, shade and average a row of pixels at a time, so no image of
sub-rays is ever held. Each gives bit for bit what casting every sub-ray (:func:`~.raycast.
cast`), shading it (:func:`aperture_radiance`, :func:`near_ir_albedo`) and averaging
(:func:`footprint_and_blur`) gives.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from functools import lru_cache
from typing import Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from ..camera import Intrinsics, RigidTransform, pixel_rays
from ..radiometry import FLIR_ATMOSPHERE, fresnel_index, water_vapour
from . import kernels
from .lepton import RadianceTable
from .raycast import Hits, grid_params, rect_params
from .scene import Checkerboard, CircleGrid, Material, Scene

FloatArray = NDArray[np.float64]


class SurfaceHits(Protocol):
    """Where rays meet the scene: rect index (-1 = nothing) and local (s, q) on it, (...)
    arrays (a camera's :class:`~.raycast.Hits`, or arbitrary rays'
    :class:`~.raycast.RayHits`)."""

    @property
    def rect(self) -> NDArray[np.int64]: ...
    @property
    def s_m(self) -> FloatArray: ...
    @property
    def q_m(self) -> FloatArray: ...


@dataclass(frozen=True, eq=False)
class SurfaceTable:
    """A scene's surfaces as the kernels read them (:mod:`.kernels` has the layouts): each
    rect's material rows, its pattern, the circle centres of circle grids, and the
    materials by row (the last row: what a ray that meets nothing sees, None)."""

    slots: NDArray[np.int64]
    pattern: FloatArray
    circles: FloatArray
    materials: tuple[Material | None, ...]

    @property
    def missed(self) -> int:
        """The row of rays that meet nothing."""
        return len(self.materials) - 1

    @classmethod
    def of(cls, scene: Scene) -> SurfaceTable:
        """The table of ``scene`` (built once per scene)."""
        table = _TABLES.get(scene)
        if table is None:
            table = _TABLES[scene] = cls._build(scene)
        return table

    @classmethod
    def _build(cls, scene: Scene) -> SurfaceTable:
        n = len(scene.rects)
        slots = np.full((n, 2), -1, np.int64)
        slots[:, 0] = np.arange(n)
        pattern = np.zeros((n, 4))
        circles: list[tuple[float, float]] = []
        seconds: list[Material] = []
        for i, rect in enumerate(scene.rects):
            if rect.pattern is None or rect.material_b is None:
                continue
            slots[i, 1] = n + len(seconds)
            seconds.append(rect.material_b)
            p = rect.pattern
            if isinstance(p, Checkerboard):
                pattern[i] = [
                    kernels.CHECKERBOARD,
                    p.board.spacing_m,
                    p.board.cols + 1,
                    p.board.rows + 1,
                ]
            elif isinstance(p, CircleGrid):
                centres = [(float(cx), float(cy)) for cx, cy, _ in p.board.object_points_m()]
                r2 = (p.diameter_m / 2) ** 2  # as CircleGrid.second_material has it
                pattern[i] = [kernels.CIRCLE_GRID, r2, len(circles), len(centres)]
                circles += centres
            else:  # pragma: no cover - every Pattern is one of the two
                raise TypeError(f"rect {rect.name!r}: unknown pattern {p!r}")
        materials = (*(r.material for r in scene.rects), *seconds, None)
        return cls(slots, pattern, np.array(circles, np.float64).reshape(-1, 2), materials)

    def values(self, name: str, missed: float) -> FloatArray:
        """One material property ``name`` (a :class:`~.scene.Material` field) by row,
        ``missed`` for rays that meet nothing."""
        return np.array(
            [missed if m is None else float(getattr(m, name)) for m in self.materials],
            np.float64,
        )

    def args(self) -> tuple[NDArray[np.int64], FloatArray, FloatArray, int]:
        """The arguments every shading kernel takes first."""
        return self.slots, self.pattern, self.circles, self.missed

    def rows_of(self, hits: SurfaceHits) -> NDArray[np.int64]:
        """The material row of each hit (the shape of ``hits.rect``)."""
        rect = np.ascontiguousarray(hits.rect, np.int64)
        out = np.empty(rect.shape, np.int64)
        kernels.material_slots(
            rect.reshape(-1),
            np.ascontiguousarray(hits.s_m, np.float64).reshape(-1),
            np.ascontiguousarray(hits.q_m, np.float64).reshape(-1),
            *self.args(),
            out.reshape(-1),
        )
        return out


_TABLES: weakref.WeakKeyDictionary[Scene, SurfaceTable] = weakref.WeakKeyDictionary()


def surface_properties(
    scene: Scene, hits: SurfaceHits
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Temperature (K), emissivity and near-IR albedo along each ray (pattern-aware).

    Rays that hit nothing get the ambient temperature, emissivity 1 and albedo 0.
    """
    table = SurfaceTable.of(scene)
    rows = table.rows_of(hits)
    return (
        table.values("temp_k", scene.ambient_temp_k)[rows],
        table.values("emissivity", 1.0)[rows],
        table.values("ir_albedo", 0.0)[rows],
    )


def near_ir_albedo(scene: Scene, hits: SurfaceHits) -> FloatArray:
    """The near-IR albedo along each ray (what the depth camera's IR image needs; 0 where
    nothing is hit): :func:`surface_properties`' third, alone."""
    table = SurfaceTable.of(scene)
    return table.values("ir_albedo", 0.0)[table.rows_of(hits)]


@lru_cache(maxsize=8)
def _thermal_tables(
    scene: Scene, table: RadianceTable
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """What the thermal shading kernels take of a scene whatever the eye: the material
    table, the rects' geometry (but the first column), their world-frame parameters and the
    air (but the eye)."""
    surfaces = SurfaceTable.of(scene)
    mat = np.zeros((len(surfaces.materials), 5))
    temps = surfaces.values("temp_k", scene.ambient_temp_k)
    emis = surfaces.values("emissivity", 1.0)
    mat[:, kernels.L_OBJ] = table.to_radiance(temps)
    mat[:, kernels.EMISSIVITY] = emis
    mat[:, kernels.INDEX_SQUARED] = np.square(fresnel_index(emis))
    mat[:, kernels.DIRECTIONAL] = surfaces.values("directional", 0.0)
    mat[:, kernels.SPECULAR] = surfaces.values("specular", 0.0)
    g = scene.geometry
    geo = np.zeros((len(scene.rects), 13))
    geo[:, 1:4], geo[:, 4:7], geo[:, 7:10], geo[:, 10:13] = (
        g.center_m,
        g.axis_u,
        g.axis_v,
        g.normal,
    )
    world = rect_params(scene, RigidTransform.identity("world", "world"))
    c = FLIR_ATMOSPHERE  # radiometry.atmospheric_transmission's terms, for one air
    sh = np.sqrt(water_vapour(scene.ambient_temp_k, scene.relative_humidity))
    l_amb = float(table.to_radiance(scene.ambient_temp_k))
    air = np.array([l_amb, -(c.alpha1 + c.beta1 * sh), -(c.alpha2 + c.beta2 * sh), c.x, 1 - c.x])
    return mat, geo, world, air


def _thermal_args(
    scene: Scene, table: RadianceTable, eye_m: FloatArray | None
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, bool]:
    """The thermal shading kernels' arguments after the surface table's: the material
    table, the rects' geometry, their world-frame parameters, the air and the eye, and
    whether mirrors reflect what they face (rays from an eye, a scene with mirrors)."""
    mat, geo, world, air = _thermal_tables(scene, table)
    if eye_m is None:
        return mat, geo, world, np.concatenate([air, np.zeros(3)]), False
    eye = np.asarray(eye_m, np.float64)
    g = scene.geometry
    geo = geo.copy()  # the distance of each rect's plane from the eye
    geo[:, 0] = np.abs(np.einsum("ij,ij->i", g.normal, g.center_m - eye))
    bounce = bool(np.any(mat[:, kernels.SPECULAR] > 0))
    return mat, geo, world, np.concatenate([air, eye]), bounce


def aperture_radiance(
    scene: Scene, hits: Hits, table: RadianceTable, eye_m: FloatArray | None = None
) -> FloatArray:
    """In-band radiance (W m^-2 sr^-1) reaching the lens along each ray of ``hits``.

    L_ap = tau(r) [eps L(T) + (1 - eps) L_r] + (1 - tau(r)) L(T_amb); rays that hit nothing
    see the enclosure at the ambient temperature. L_r, the radiance the surface reflects, is
    the ambient's L(T_amb), unless its material is specular: then the radiance its mirrored
    ray meets, one bounce (the surface there at its temperature and emissivity, reflecting
    the ambient, through the air between; the ambient if it meets nothing). eps is the
    material's, or for a directional one its Fresnel emissivity at the angle of view
    (:func:`~thermodepth.radiometry.fresnel_emissivity`). ``eye_m`` (3,): the camera's
    centre in the world, needed when the scene has directional or specular materials.
    """
    if scene.has_optics and eye_m is None:
        raise ValueError("a scene with directional or specular materials needs the eye_m")
    out = np.empty(hits.rect.shape)
    kernels.radiance_rays(
        np.ascontiguousarray(hits.rect, np.int64).reshape(-1),
        np.ascontiguousarray(hits.s_m, np.float64).reshape(-1),
        np.ascontiguousarray(hits.q_m, np.float64).reshape(-1),
        np.ascontiguousarray(hits.range_m, np.float64).reshape(-1),
        *SurfaceTable.of(scene).args(),
        *_thermal_args(scene, table, eye_m),
        out.reshape(-1),
    )
    return out


def footprint_and_blur(
    sub_radiance: FloatArray, supersample: int, psf_sigma_px: float
) -> FloatArray:
    """Mean over each pixel's sub-rays, then the optics' Gaussian PSF (sigma in pixels).

    sub_radiance (h ss, w ss) -> (h, w); the mean is numpy's ``reshape(h, ss, w,
    ss).mean(axis=(1, 3))``, bit for bit."""
    _check_supersample(supersample)
    h, w = sub_radiance.shape[0] // supersample, sub_radiance.shape[1] // supersample
    pix = np.empty((h, w))
    kernels.footprint(np.ascontiguousarray(sub_radiance, np.float64), supersample, pix)
    return _blur(pix, psf_sigma_px)


def _blur(pix: FloatArray, psf_sigma_px: float) -> FloatArray:
    if psf_sigma_px > 0:
        return np.asarray(
            cv2.GaussianBlur(pix, (0, 0), psf_sigma_px, borderType=cv2.BORDER_REFLECT)
        )
    return pix


def _check_supersample(supersample: int) -> None:
    if not 1 <= supersample <= kernels.MAX_SUPERSAMPLE:
        raise ValueError(f"supersample must be 1-{kernels.MAX_SUPERSAMPLE}, got {supersample}")


def render_aperture(
    scene: Scene,
    camera_from_world: RigidTransform,
    intr: Intrinsics,
    supersample: int,
    psf_sigma_px: float,
    table: RadianceTable,
) -> FloatArray:
    """The aperture radiance a thermal camera sees, (h, w) W m^-2 sr^-1: each pixel the mean
    of its supersample x supersample sub-rays' :func:`aperture_radiance` (the camera's
    centre the eye), then the optics' Gaussian PSF (sigma in pixels); bit for bit
    ``footprint_and_blur(aperture_radiance(scene, cast(...), ...), ...)``."""
    _check_supersample(supersample)
    xs, ys = pixel_rays(intr, supersample)
    eye_m = camera_from_world.inverse().translation_m
    pix = np.empty((intr.height, intr.width))
    kernels.render_radiance(
        xs,
        ys,
        supersample,
        *grid_params(scene, camera_from_world, intr, supersample),
        *SurfaceTable.of(scene).args(),
        *_thermal_args(scene, table, eye_m),
        pix,
    )
    return _blur(pix, psf_sigma_px)


def render_ir_albedo(
    scene: Scene, camera_from_world: RigidTransform, intr: Intrinsics, supersample: int
) -> FloatArray:
    """The near-IR albedo a depth camera's IR imager sees, (H, W): each pixel the mean of
    its supersample x supersample sub-rays' :func:`near_ir_albedo`; bit for bit
    ``footprint_and_blur(near_ir_albedo(scene, cast(...)), supersample, 0)``."""
    _check_supersample(supersample)
    xs, ys = pixel_rays(intr, supersample)
    surfaces = SurfaceTable.of(scene)
    pix = np.empty((intr.height, intr.width))
    kernels.render_albedo(
        xs,
        ys,
        supersample,
        *grid_params(scene, camera_from_world, intr, supersample),
        *surfaces.args(),
        surfaces.values("ir_albedo", 0.0),
        pix,
    )
    return pix
