"""``paper``: Lin & Yao 2022, sections 2.1-2.2. The thermal image is undistorted, then
cropped/offset and upscaled to the depth grid with nearest neighbour: an affine map that is
right at one reference distance only (parallax error elsewhere). No occlusion test."""

from __future__ import annotations

from typing import ClassVar

import cv2
import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from ..camera import distort, pixel_rays
from .base import (
    DepthOnThermal,
    FloatArray,
    Reason,
    RegistrationOptions,
    RowSums,
    ThermalOnDepth,
)
from .kernels import scan_regions


class PaperMethod:
    """The paper's registration (section 2.2) as fixed lookups: a crop/offset + upscale from
    depth pixels to undistorted thermal pixels, u_t = a_u u + b_u, v_t = a_v v + b_v, with the
    affine fitted (least squares) to the exact mapping of a plane at
    ``options.paper_reference_m`` (the paper sets it by hand at its working distance). All
    that does not depend on the frame is computed here, once."""

    name: ClassVar[str] = "paper"

    def __init__(self, calibration: Calibration, options: RegistrationOptions) -> None:
        self.calibration = cal = calibration
        d, t = cal.depth, cal.thermal
        a_u, b_u, a_v, b_v = _fit_affine(cal, options.paper_reference_m)
        # depth -> thermal: the raw thermal (u, v) each depth pixel samples (undistorting the
        # thermal image = sampling it at the distorted position)
        u, v = d.pixel_grid()
        xd, yd = distort((a_u * u + b_u - t.cx) / t.fx, (a_v * v + b_v - t.cy) / t.fy, t.distortion)
        self.map_u = (t.fx * xd + t.cx).astype(np.float32)
        self.map_v = (t.fy * yd + t.cy).astype(np.float32)
        self.inside = t.contains(np.stack([self.map_u, self.map_v], axis=-1))
        nearest = np.rint(self.map_v) * t.width + np.rint(self.map_u)
        self.index = np.where(self.inside, nearest, -1).astype(np.int32)
        # thermal -> depth: the depth pixel the upscale puts on each thermal pixel's centre
        x, y = pixel_rays(t)
        cols = np.rint((t.fx * x + t.cx - b_u) / a_u).astype(np.int64)
        rows = np.rint((t.fy * y + t.cy - b_v) / a_v).astype(np.int64)
        self.seen = (cols >= 0) & (cols < d.width) & (rows >= 0) & (rows < d.height)
        self.source = np.where(self.seen, rows * d.width + cols, 0)
        xs, ys = d.normalized_from_pixels(np.stack([cols, rows], axis=-1))
        self.range_per_z = np.sqrt(xs * xs + ys * ys + 1).astype(np.float32)
        self.scale = np.float32(cal.depth_scale_m)

    def thermal_to_depth(
        self,
        depth: NDArray[np.uint16],
        thermal: FloatArray,
        interpolation: str,
        nearest: DepthOnThermal | None,
        thermal_index: NDArray[np.int32] | None,
        regions: RowSums,
    ) -> ThermalOnDepth:
        """No occlusion test (the paper has none); ``nearest`` is not needed. The regions are
        summed in a pass of their own over the sampled image."""
        flag = cv2.INTER_NEAREST if interpolation == "nearest" else cv2.INTER_LINEAR
        out = cv2.remap(
            thermal,
            self.map_u,
            self.map_v,
            flag,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=np.nan,
        )
        valid = depth != 0
        reason = np.where(
            valid, np.where(self.inside, Reason.OK, Reason.OUTSIDE), Reason.INVALID_DEPTH
        ).astype(np.uint8)
        ok = valid & self.inside
        out[~ok] = np.nan
        if thermal_index is not None:
            np.copyto(thermal_index, np.where(ok, self.index, np.int32(-1)))
        values: FloatArray = np.asarray(out, dtype=np.float32)
        if regions.boxes.shape[0]:
            scan_regions(depth, values, reason, self.index, regions)
        return ThermalOnDepth(values, reason)

    def depth_to_thermal(self, depth: NDArray[np.uint16]) -> DepthOnThermal:
        """Z (and range) in the depth camera's frame of the depth pixel under each thermal
        pixel's centre."""
        units = np.where(self.seen, depth.ravel()[self.source], 0)
        z = np.where(units > 0, units * self.scale, np.float32(np.nan)).astype(np.float32)
        return DepthOnThermal(z, z * self.range_per_z)

    def thermal_pixel_of_depth(
        self, depth: NDArray[np.uint16]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The upscale's fixed map (the same at every depth), NaN where the depth is invalid."""
        valid = depth > 0
        return (
            np.where(valid, self.map_u, np.nan).astype(np.float64),
            np.where(valid, self.map_v, np.nan).astype(np.float64),
        )


def _fit_affine(cal: Calibration, distance_m: float) -> tuple[float, float, float, float]:
    """(a_u, b_u, a_v, b_v) of the upscale, fitted by least squares to the exact mapping of a
    plane facing the depth camera at ``distance_m``."""
    d, t = cal.depth, cal.thermal
    u, v = d.pixel_grid()
    uu, vv = u[::8, ::8], v[::8, ::8]
    pts = cal.thermal_from_depth.apply(d.deproject(np.stack([uu, vv], -1), distance_m))
    x, y = pts[..., 0] / pts[..., 2], pts[..., 1] / pts[..., 2]
    und_u, und_v = t.fx * x + t.cx, t.fy * y + t.cy
    ok = t.contains(np.stack([und_u, und_v], axis=-1))
    a_u, b_u = np.polyfit(uu[ok], und_u[ok], 1)
    a_v, b_v = np.polyfit(vv[ok], und_v[ok], 1)
    return float(a_u), float(b_u), float(a_v), float(b_v)
