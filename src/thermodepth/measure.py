"""Measurements on fused frames: ROI statistics, spot temperatures, hotspots in 3D (the
alarm rules that watch them: :mod:`thermodepth.alarms`).

Pure functions over arrays; the pipeline calls them on every fused frame. Temperatures in
Celsius (the user's unit), lengths in metres, areas in m^2, power in watts.

Hotspots are connected regions of thermal pixels at or above a threshold, found on the
thermal grid (the temperature's own resolution). Their geometry comes from the depth
camera: each pixel's surface point (the z-buffer's nearest Z), a plane fitted through them,
and each thermal pixel's footprint on that plane (its four corner rays intersected with it).
So the area is in m^2 on the surface, whatever the distance and the tilt. A hotspot smaller
than 3 x 3 thermal pixels is not ``resolvable``: its reading is biased low (the pixel
footprint and optics blur average it with its surroundings), the usual measurement-spot rule.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from .camera import Intrinsics, RigidTransform, corner_rays, pixel_rays
from .isotherms import IsothermRoi
from .lines import LineRoi
from .radiometry import celsius_to_kelvin, stefan_boltzmann_power_w
from .registration.kernels import FIXED_POINT, VALUE_LIMIT
from .registration.regions import Moments, Region, exact_sum

FloatArray = NDArray[np.floating]
BoolArray = NDArray[np.bool_]


# ---------------------------------------------------------------------------------------------
# ROIs
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RectRoi:
    """Pixels u0 <= u < u1, v0 <= v < v1 of the depth image."""

    name: str
    u0: int
    v0: int
    u1: int
    v1: int

    def mask(self, shape: tuple[int, int], depth_m: FloatArray | None = None) -> BoolArray:
        m = np.zeros(shape, dtype=bool)
        # clipped at 0 at both ends: a negative end would count from the far edge
        m[max(self.v0, 0) : max(self.v1, 0), max(self.u0, 0) : max(self.u1, 0)] = True
        return m


@dataclass(frozen=True)
class PolygonRoi:
    """The inside of a polygon of depth-image pixel vertices [(u, v), ...]."""

    name: str
    vertices: tuple[tuple[float, float], ...]

    def mask(self, shape: tuple[int, int], depth_m: FloatArray | None = None) -> BoolArray:
        m = np.zeros(shape, dtype=np.uint8)
        pts = np.round(np.asarray(self.vertices, np.float64)).astype(np.int32)
        cv2.fillPoly(m, [pts], 1)
        return m.astype(bool)


@dataclass(frozen=True)
class DepthRangeRoi:
    """Everything between ``near_m`` and ``far_m`` from the depth camera (Z)."""

    name: str
    near_m: float
    far_m: float

    def mask(self, shape: tuple[int, int], depth_m: FloatArray | None = None) -> BoolArray:
        if depth_m is None:
            raise ValueError(f"ROI {self.name!r}: a depth range needs the depth map")
        with np.errstate(invalid="ignore"):
            return (depth_m >= self.near_m) & (depth_m <= self.far_m)


Roi = RectRoi | PolygonRoi | DepthRangeRoi | LineRoi | IsothermRoi
Box = tuple[slice, slice]
"""Rows and columns of an image, as slices."""


def bounding_box(mask: BoolArray) -> Box:
    """The smallest (rows, columns) slices that hold every True of a 2-D ``mask`` (empty
    slices when it has none): a fixed ROI's statistics then gather from its box only."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return slice(0, 0), slice(0, 0)
    return slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1)


@dataclass(frozen=True)
class RoiStats:
    """Statistics of the valid temperatures inside an ROI (C); n = 0 means none was valid.
    flags: OR of the compensation flags of the pixels it covers."""

    name: str
    n: int
    mean_c: float
    max_c: float
    min_c: float
    sd_c: float
    flags: int = 0
    severity: dict[str, Any] | None = None  # its class (thermodepth.severity), if it has one

    @classmethod
    def of(cls, name: str, moments: Moments) -> RoiStats:
        """The statistics of an ROI's exact sums (of temperatures in C)."""
        m = moments
        return cls(name, m.n, m.mean, m.max, m.min, m.sd, m.flags)


def _fixed(values: NDArray[np.floating]) -> NDArray[np.int64]:
    """Temperatures (C) as whole multiples of 2^-12 C, as the registration's kernel sums them
    (:data:`~thermodepth.registration.kernels.FIXED_POINT`): float32, clipped to +-8191 C,
    scaled (exactly: a power of two) and rounded half up."""
    t = np.clip(values.astype(np.float32), -VALUE_LIMIT, VALUE_LIMIT)
    return np.floor(t * np.float32(FIXED_POINT) + np.float32(0.5)).astype(np.int64)


def roi_stats(
    name: str, temp_c: FloatArray, mask: BoolArray, flags: NDArray[np.uint8] | None = None
) -> RoiStats:
    """Mean, max, min and SD of finite ``temp_c`` inside ``mask`` (same shape); ``flags``
    (any shape): those of the pixels the ROI draws on, OR-ed into its flag. The sums are
    exact (whole multiples of 2^-12 C, 0.00024 C, far below any camera's noise): the
    pipeline's, taken while it samples (:mod:`thermodepth.registration.regions`), are the
    same figures."""
    values = temp_c[mask]
    values = values[np.isfinite(values)]
    flag = int(np.bitwise_or.reduce(flags, axis=None, initial=0)) if flags is not None else 0
    if values.size == 0:
        return RoiStats.of(name, Moments.none(flag))
    q = _fixed(values)
    moments = Moments(
        int(values.size),
        int(q.sum()),
        int(exact_sum(q * q)),
        float(values.min()),
        float(values.max()),
        flag,
    )
    return RoiStats.of(name, moments)


def roi_region(roi: Roi, shape: tuple[int, int], depth_scale_m: float) -> Region:
    """Where ``roi``'s pixels are on a depth image of ``shape`` (H, W), as the registration
    sums them: a rectangle is its box, a polygon its box and mask, a depth range the whole
    image and the raw depth values whose Z (float32 metres, as
    :attr:`~thermodepth.pipeline.FusedFrame.depth_m`) lies in it."""
    if isinstance(roi, DepthRangeRoi):
        units = np.arange(65536, dtype=np.uint16)
        z = units.astype(np.float32) * np.float32(depth_scale_m)
        inside = np.flatnonzero((units > 0) & (z >= roi.near_m) & (z <= roi.far_m))
        span = (int(inside[0]), int(inside[-1])) if inside.size else (1, 0)
        return Region(
            slice(0, shape[0]), slice(0, shape[1]), np.ones((1, shape[1]), np.uint8), span
        )
    mask = roi.mask(shape)
    rows, cols = bounding_box(mask)
    if isinstance(roi, RectRoi):
        return Region(rows, cols, np.ones((1, cols.stop - cols.start), np.uint8))
    return Region(rows, cols, np.ascontiguousarray(mask[rows, cols], np.uint8))


# ---------------------------------------------------------------------------------------------
# Spots
# ---------------------------------------------------------------------------------------------


def spot_at_point(
    point_m: Sequence[float],
    temp_thermal_c: FloatArray,
    z_thermal_m: FloatArray,
    thermal: Intrinsics,
    thermal_from_depth: RigidTransform,
    tolerance_m: float = 0.05,
) -> float:
    """Temperature (C) of the surface at a 3D point (depth camera frame, metres): the thermal
    pixel it projects to, provided that pixel's nearest surface is the point's (within
    ``tolerance_m``); NaN if hidden or outside the thermal image."""
    p = thermal_from_depth.apply(np.asarray(point_m, np.float64))
    px = thermal.project(p)
    if not np.all(np.isfinite(px)) or not thermal.contains(px):
        return float("nan")
    u, v = (int(np.floor(c + 0.5)) for c in px)
    if not abs(float(z_thermal_m[v, u]) - p[2]) <= tolerance_m:
        return float("nan")
    return float(temp_thermal_c[v, u])


# ---------------------------------------------------------------------------------------------
# Hotspots
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Hotspot:
    """A connected region of thermal pixels at or above the threshold.

    max_c, mean_c: temperature (C); centroid_m: area-weighted surface centroid in the depth
    camera's frame (m); distance_m: its distance from the depth camera; area_m2: the surface
    it covers; thermal_px: how many thermal pixels; bbox_thermal: (u0, v0, u1, v1) inclusive;
    resolvable: its core (pixels within 10 % of its excess over the threshold from the
    maximum) holds a full 3 x 3 block (otherwise its reading is biased low);
    power_w: net radiated power, sum over its pixels of A eps sigma (T^4 - T_amb^4)
    (paper eq. 14); flags: OR of the compensation flags of its pixels; label: its index.
    """

    label: int
    max_c: float
    mean_c: float
    centroid_m: tuple[float, float, float]
    distance_m: float
    area_m2: float
    thermal_px: int
    bbox_thermal: tuple[int, int, int, int]
    resolvable: bool
    power_w: float
    flags: int = 0
    pixels: NDArray[np.int64] = field(
        default_factory=lambda: np.zeros(0, np.int64), repr=False, compare=False
    )

    def as_dict(self) -> dict[str, Any]:
        d = {k: v for k, v in self.__dict__.items() if k != "pixels"}
        d["centroid_m"] = list(self.centroid_m)
        d["bbox_thermal"] = list(self.bbox_thermal)
        return d


def _plane(points: FloatArray) -> tuple[FloatArray, FloatArray] | None:
    """Centroid and unit normal of the least-squares plane, or None if degenerate."""
    if len(points) < 3:
        return None
    c = points.mean(axis=0)
    _, s, vt = np.linalg.svd(points - c, full_matrices=False)
    if s[1] < 1e-9:  # collinear
        return None
    return c, vt[2]


@lru_cache(maxsize=8)
def _pixel_corners(thermal: Intrinsics) -> FloatArray:
    """Each pixel's four corner rays (h, w, 4, 3): top-left, top-right, bottom-right,
    bottom-left, as (x, y, 1) undistorted. Cached per camera."""
    cx, cy = corner_rays(thermal)
    x = np.stack([cx[:-1, :-1], cx[:-1, 1:], cx[1:, 1:], cx[1:, :-1]], axis=-1)
    y = np.stack([cy[:-1, :-1], cy[:-1, 1:], cy[1:, 1:], cy[1:, :-1]], axis=-1)
    return np.stack([x, y, np.ones_like(x)], axis=-1)


def _footprints(
    u: NDArray[np.int64],
    v: NDArray[np.int64],
    thermal: Intrinsics,
    plane: tuple[FloatArray, FloatArray],
) -> FloatArray:
    """Area (m^2) of thermal pixels' (u, v) footprints on a plane (thermal frame): the four
    corner rays intersected with the plane, the quadrilateral's area."""
    c, n = plane
    rays = _pixel_corners(thermal)[v, u]  # (N, 4, 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (c @ n) / (rays @ n)
    q = rays * t[..., None]
    # half the cross product of the diagonals, written out: np.cross and norm cost 4x more
    a, b = (q[:, 2] - q[:, 0]).T, (q[:, 3] - q[:, 1]).T
    cx, cy, cz = a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]
    area = 0.5 * np.sqrt(cx * cx + cy * cy + cz * cz)
    return np.where(np.isfinite(area) & (t > 0).all(axis=1), area, np.nan)


@lru_cache(maxsize=8)
def _inverse(t: RigidTransform) -> RigidTransform:
    return t.inverse()


def find_hotspots(
    temp_thermal_c: FloatArray,
    z_thermal_m: FloatArray,
    threshold_c: float,
    thermal: Intrinsics,
    thermal_from_depth: RigidTransform,
    ambient_temp_c: float,
    emissivity: float = 0.95,
    flags: NDArray[np.uint8] | None = None,
    min_thermal_px: int = 1,
) -> list[Hotspot]:
    """Hotspots of a thermal-grid temperature map (h, w), hottest first.

    z_thermal_m: the nearest surface's Z per thermal pixel (registration's depth_to_thermal),
    NaN where unknown: those pixels count in the region but not in its geometry.
    """
    with np.errstate(invalid="ignore"):
        hot = (temp_thermal_c >= threshold_c).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(hot, connectivity=8)
    depth_from_thermal = _inverse(thermal_from_depth)
    ambient_k = celsius_to_kelvin(ambient_temp_c)
    rx, ry = pixel_rays(thermal)
    out = []
    for k in range(1, n):
        if stats[k, cv2.CC_STAT_AREA] < min_thermal_px:
            continue
        x0, y0 = stats[k, cv2.CC_STAT_LEFT], stats[k, cv2.CC_STAT_TOP]
        bw, bh = stats[k, cv2.CC_STAT_WIDTH], stats[k, cv2.CC_STAT_HEIGHT]
        mine = labels[y0 : y0 + bh, x0 : x0 + bw] == k  # look only inside its box
        v, u = np.nonzero(mine)
        v, u = v + y0, u + x0
        temps = temp_thermal_c[v, u]  # all above the threshold: finite
        z = z_thermal_m[v, u]
        known = np.isfinite(z)
        zk = z[known]
        pts_t = np.stack([rx[v[known], u[known]] * zk, ry[v[known], u[known]] * zk, zk], -1)
        plane = _plane(pts_t)
        if plane is None and known.any():  # too few points: face the camera at their depth
            c = pts_t.mean(axis=0)
            plane = (c, c / np.linalg.norm(c))
        area = _footprints(u[known], v[known], thermal, plane) if plane is not None else np.zeros(0)
        good = np.isfinite(area)
        if good.any():
            w = area[good]
            centroid_t = (pts_t[good] * w[:, None]).sum(axis=0) / w.sum()
            centroid = depth_from_thermal.apply(centroid_t)
            surface_k = celsius_to_kelvin(temps[known][good])
            power = float(np.sum(stefan_boltzmann_power_w(w, emissivity, surface_k, ambient_k)))
            area_m2 = float(w.sum())
        else:
            centroid = np.full(3, np.nan)
            power = area_m2 = float("nan")
        # the blur spreads a small target over a halo above the threshold: judge the spot
        # rule on its core, the pixels within 10 % of its excess over the threshold from the
        # maximum (a target that fills 3 x 3 pixels reads flat there)
        box = temp_thermal_c[y0 : y0 + bh, x0 : x0 + bw]
        t_max = float(temps.max())
        with np.errstate(invalid="ignore"):
            core_px = mine & (box >= t_max - 0.1 * (t_max - threshold_c))
        core = cv2.erode(
            core_px.astype(np.uint8),
            np.ones((3, 3), np.uint8),
            borderType=cv2.BORDER_CONSTANT,
            borderValue=0,
        )
        flag = int(np.bitwise_or.reduce(flags[v, u], initial=0)) if flags is not None else 0
        out.append(
            Hotspot(
                label=k,
                max_c=t_max,
                mean_c=float(temps.mean()),
                centroid_m=(float(centroid[0]), float(centroid[1]), float(centroid[2])),
                distance_m=float(np.linalg.norm(centroid)),
                area_m2=area_m2,
                thermal_px=int(u.size),
                bbox_thermal=(int(x0), int(y0), int(x0 + bw - 1), int(y0 + bh - 1)),
                resolvable=bool(core.any()),
                power_w=power,
                flags=flag,
                pixels=(v * temp_thermal_c.shape[1] + u).astype(np.int64),
            )
        )
    out.sort(key=lambda h: -h.max_c)
    return out


def hotspot_box_on_depth(
    hotspot: Hotspot,
    z_thermal_m: FloatArray,
    thermal: Intrinsics,
    depth: Intrinsics,
    thermal_from_depth: RigidTransform,
) -> tuple[int, int, int, int] | None:
    """Bounding box (u0, v0, u1, v1) in the depth image of a hotspot's surface points (its
    thermal pixels' corners at their depth); None when none of them has a depth."""
    w_t = z_thermal_m.shape[1]
    v, u = np.divmod(hotspot.pixels, w_t)
    z = z_thermal_m[v, u]
    ok = np.isfinite(z)
    if not ok.any():
        return None
    pts = _pixel_corners(thermal)[v[ok], u[ok]] * z[ok][:, None, None]  # (N, 4, 3)
    px = depth.project(_inverse(thermal_from_depth).apply(pts)).reshape(-1, 2)
    px = px[np.isfinite(px).all(axis=1)]
    if px.size == 0:
        return None
    lo = np.clip(np.floor(px.min(axis=0)), 0, [depth.width - 1, depth.height - 1])
    hi = np.clip(np.ceil(px.max(axis=0)), 0, [depth.width - 1, depth.height - 1])
    return int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1])
