"""``reproject``: every depth pixel deprojected with its depth, moved into the thermal frame
and projected through the thermal lens (OpenCV distortion, refused beyond the radius where
the polynomial folds), with a z-buffer test so that a surface hidden from the thermal camera
does not take the temperature of what hides it. Exact up to the depth noise.

Where the thermal camera's pixels are finer than the depth camera's (a Boson 640 beside a
D435 at 848x480: neighbouring depth pixels land 1.6 thermal pixels apart), each depth pixel
covers more than the thermal pixel it lands in; the z-buffer then takes, for every thermal
pixel, the nearest surface within the depth pixels' spacing (:func:`dilation_radius`), so that
it has no holes through which a hidden surface would take the temperature of what hides it."""

from __future__ import annotations

from typing import ClassVar

import numba
import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from ..camera import pixel_rays
from .base import DepthOnThermal, FloatArray, RegistrationOptions, RowSums, ThermalOnDepth
from .kernels import (
    FAR_M,
    W_SAMPLES,
    Lens,
    Rays,
    Sampled,
    Sampling,
    ViewTable,
    dilate_keys,
    sample,
    sampling_lag,
    view_table,
    zbuffer,
)


def lens_of(calibration: Calibration) -> Lens:
    """The thermal camera and the translation of ``thermal_from_depth``, as the kernels take
    them (float32; an unbounded valid radius capped at 1e30)."""
    t = calibration.thermal
    values = (
        *calibration.thermal_from_depth.translation_m,
        t.fx,
        t.fy,
        t.cx,
        t.cy,
        *t.distortion,
        min(t.max_radius2, 1e30),
        t.width,
        t.height,
    )
    return Lens(*(np.float32(v) for v in values))


def rays_of(cal: Calibration) -> Rays:
    """R @ ray of every depth pixel as :class:`~.kernels.Rays`, float32.

    R ray = x R[:, 0] + y R[:, 1] + R[:, 2] with x per column and y per row when the depth
    camera has no distortion: A_u = x_u R[:, 0] (shape (1, W) each), B_v = y_v R[:, 1] +
    R[:, 2]. With distortion the rays are not separable: A holds R @ ray for every pixel
    (H, W) and B is zero.
    """
    d = cal.depth
    rot = cal.thermal_from_depth.rotation
    if not d.has_distortion:
        x = (np.arange(d.width) - d.cx) / d.fx
        y = (np.arange(d.height) - d.cy) / d.fy
        a = [np.ascontiguousarray((x * rot[i, 0])[None, :], dtype=np.float32) for i in range(3)]
        b = y[:, None] * rot[:, 1] + rot[:, 2]
        return Rays(a[0], a[1], a[2], np.ascontiguousarray(b, dtype=np.float32))
    x, y = pixel_rays(d)
    a = [
        np.ascontiguousarray(x * rot[i, 0] + y * rot[i, 1] + rot[i, 2], dtype=np.float32)
        for i in range(3)
    ]
    return Rays(a[0], a[1], a[2], np.zeros((d.height, 3), dtype=np.float32))


SPACING_DISTANCES_M = (0.3, 0.5, 1.0, 2.0, 5.0)
"""Distances (Z, m) at which the spacing of neighbouring depth pixels in the thermal image is
measured (:func:`depth_pixel_spacing`): the baseline's parallax changes it a little with
distance."""


def depth_pixel_spacing(calibration: Calibration, step: int = 8) -> float:
    """The largest distance (thermal pixels, along u or v) between where two neighbouring
    depth pixels land in the thermal image, over every ``step``-th depth pixel that lands
    inside it at :data:`SPACING_DISTANCES_M`: about fx_thermal / fx_depth, and below 1 when
    the thermal camera's pixels are coarser than the depth camera's."""
    cal = calibration
    u, v = np.meshgrid(
        np.arange(0, cal.depth.width - 1, step, dtype=np.float64),
        np.arange(0, cal.depth.height - 1, step, dtype=np.float64),
    )
    px = np.stack([u.ravel(), v.ravel()], -1)
    spacing = 0.0
    for z in SPACING_DISTANCES_M:
        here, right, below = (
            cal.thermal.project(cal.thermal_from_depth.apply(cal.depth.deproject(q, z)))
            for q in (px, px + np.array([1.0, 0.0]), px + np.array([0.0, 1.0]))
        )
        inside = cal.thermal.contains(here)
        if inside.any():
            steps = np.abs(np.concatenate([right - here, below - here], axis=1))[inside]
            spacing = max(spacing, float(steps.max()))
    return spacing


def dilation_radius(spacing_px: float) -> int:
    """Thermal pixels each way the z-buffer looks around a pixel for the nearest surface when
    depth pixels land ``spacing_px`` apart: a box of 2 r + 1 >= spacing pixels holds one of
    them wherever the thermal pixel lies (0: no holes, thermal pixels coarser)."""
    return max(0, int(np.ceil((spacing_px - 1.0) / 2.0)))


class ReprojectMethod:
    """Exact, occlusion-aware registration (see the module docstring). Everything that does
    not depend on the frame (rays, the lens, the view table) is computed once, here."""

    name: ClassVar[str] = "reproject"

    def __init__(self, calibration: Calibration, options: RegistrationOptions) -> None:
        self.calibration = calibration
        self._scale = np.float32(calibration.depth_scale_m)
        self._rays = rays_of(calibration)
        self._lens = lens_of(calibration)
        self._n_chunks = options.chunks or max(1, numba.get_num_threads())
        h = calibration.depth.height
        self._view = ViewTable(
            np.empty((h, W_SAMPLES), dtype=np.int32),
            np.empty((h, W_SAMPLES), dtype=np.int32),
            np.empty((h, W_SAMPLES, 2), dtype=np.int32),
        )
        view_table(self._scale, self._rays, self._lens, self._view)
        self.dilation = dilation_radius(depth_pixel_spacing(calibration))
        tol_sigma, tol_slope = options.tolerance.coefficients(calibration)
        self._sampling = {
            bilinear: Sampling(
                sampling_lag(self._view.reach),
                np.float32(tol_sigma),
                np.float32(tol_slope),
                bilinear,
                self._n_chunks,
            )
            for bilinear in (False, True)
        }

    def _zbuffer(self, depth: NDArray[np.uint16]) -> tuple[FloatArray, FloatArray]:
        """Nearest Z per thermal pixel and that point's range, flat (h * w) views, inf / NaN
        where no depth pixel lands (within :attr:`dilation` pixels, when thermal pixels are
        finer than depth pixels)."""
        h_t, w_t = self.calibration.thermal.shape
        keys = np.empty((self._n_chunks, h_t * w_t), dtype=np.uint64)
        zbuffer(depth, self._scale, self._rays, self._lens, self._view, keys)
        nearest = keys[0]
        if self.dilation:
            grid = nearest.reshape(h_t, w_t)
            nearest = np.empty_like(grid)
            dilate_keys(grid, self.dilation, np.empty_like(grid), nearest)
            nearest = nearest.ravel()
        halves = nearest.view(np.float32)  # little-endian: range, then Z
        return halves[1::2], halves[0::2]

    def depth_to_thermal(self, depth: NDArray[np.uint16]) -> DepthOnThermal:
        zbuf, rbuf = self._zbuffer(depth)
        shape = self.calibration.thermal.shape
        z_m = np.where(np.isfinite(zbuf), zbuf, np.float32(np.nan)).reshape(shape)
        return DepthOnThermal(z_m, np.ascontiguousarray(rbuf).reshape(shape))

    def thermal_to_depth(
        self,
        depth: NDArray[np.uint16],
        thermal: FloatArray,
        interpolation: str,
        nearest: DepthOnThermal | None,
        thermal_index: NDArray[np.int32] | None,
        regions: RowSums,
    ) -> ThermalOnDepth:
        if nearest is None and self.dilation:  # holes to fill first: the whole z-buffer
            nearest = self.depth_to_thermal(depth)
        if nearest is None:  # the sampling kernel builds its own z-buffer
            zbuf = np.full(thermal.size, FAR_M, dtype=np.float32)
        else:
            zbuf = np.where(np.isnan(nearest.z_m), FAR_M, nearest.z_m).ravel()
        into = Sampled(
            np.empty(depth.shape, dtype=np.float32),
            np.empty(depth.shape, dtype=np.uint8),
            thermal_index if thermal_index is not None else np.empty((1, 1), np.int32),
            thermal_index is not None,
            np.zeros(self._n_chunks, dtype=np.uint8),
        )
        how = self._sampling[interpolation == "bilinear"]
        values = thermal.ravel()
        args = (depth, self._scale, self._rays, self._lens, self._view, values)
        sample(*args, zbuf, nearest is None, how, into, regions)
        if into.near.any():
            # depth nearer than the view table reaches: those pixels can land in any thermal
            # row, beyond the lag rows a chunk takes in, so build the whole z-buffer first
            sample(*args, np.minimum(self._zbuffer(depth)[0], FAR_M), False, how, into, regions)
        return ThermalOnDepth(into.values, into.reason)

    def thermal_pixel_of_depth(
        self, depth: NDArray[np.uint16]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Computed plainly in float64 (what the kernels compute in float32), for evaluation."""
        cal = self.calibration
        u, v = cal.depth.pixel_grid()
        z_m = np.where(depth > 0, depth * cal.depth_scale_m, np.nan)
        points = cal.thermal_from_depth.apply(cal.depth.deproject(np.stack([u, v], -1), z_m))
        with np.errstate(invalid="ignore"):
            px = cal.thermal.project(points)
        return px[..., 0], px[..., 1]
