"""Measurements on fused frames: ROI statistics, spot temperatures, hotspots in 3D, alarms.

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

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import cv2
import numba
import numpy as np
from numpy.typing import NDArray

from .camera import Intrinsics, RigidTransform, corner_rays, pixel_rays
from .radiometry import celsius_to_kelvin, stefan_boltzmann_power_w

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


Roi = RectRoi | PolygonRoi | DepthRangeRoi
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


FIXED_POINT = 2**12
"""Temperatures are summed as whole multiples of 2^-12 C (0.00024 C, far below any camera's
noise), rounded: integer sums are exact, so an ROI's statistics do not depend on the order
its pixels are visited in (rows, threads, vector lanes), and a box scan equals a whole-image
mask bit for bit."""

_T_LIMIT_C = 8191.0  # temperatures clipped to +-8191 C: q^2 over a row fits int64
_NO_MIN, _NO_MAX = np.int32(2**31 - 1), np.int32(-(2**31))


@dataclass(frozen=True)
class RoiMoments:
    """Exact sums over an ROI's valid pixels: n, the sums of q and of q^2 (ints), with q the
    temperature in units of 2^-12 C (:data:`FIXED_POINT`); the extremes (C) and the OR of
    the flags."""

    n: int
    sum_q: int
    sum_q2: int
    min_c: float
    max_c: float
    flags: int

    def stats(self, name: str) -> RoiStats:
        """Mean, max, min and SD (of the population, as numpy's std) in C."""
        if self.n == 0:
            nan = float("nan")
            return RoiStats(name, 0, nan, nan, nan, nan, self.flags)
        n, s = self.n, self.sum_q
        spread = n * self.sum_q2 - s * s  # exact: n^2 times the variance, in q units
        return RoiStats(
            name,
            n,
            s / n / FIXED_POINT,
            self.max_c,
            self.min_c,
            float(np.sqrt(spread / (n * n))) / FIXED_POINT,
            self.flags,
        )


def _fixed(values: NDArray[np.floating]) -> NDArray[np.int64]:
    """Temperatures (C) as whole multiples of 2^-12 C, as the pipeline's kernel computes them:
    float32, clipped to +-8191 C, scaled (exactly: a power of two) and rounded half up."""
    t = np.clip(values.astype(np.float32), -_T_LIMIT_C, _T_LIMIT_C)
    return np.floor(t * np.float32(FIXED_POINT) + np.float32(0.5)).astype(np.int64)


def _exact_sum(values: NDArray[np.int64]) -> int:
    """The sum of up to 2^21 int64 values as an exact int (their total may not fit int64):
    the high and low 32 bits summed apart."""
    return (int((values >> 32).sum()) << 32) + int((values & 0xFFFFFFFF).sum())


def roi_stats(
    name: str, temp_c: FloatArray, mask: BoolArray, flags: NDArray[np.uint8] | None = None
) -> RoiStats:
    """Mean, max, min and SD of finite ``temp_c`` inside ``mask`` (same shape); ``flags``
    (any shape): those of the pixels the ROI draws on, OR-ed into its flag. The sums are
    exact (:data:`FIXED_POINT`): the pipeline's :func:`scan_roi` gives the same figures."""
    values = temp_c[mask]
    values = values[np.isfinite(values)]
    flag = int(np.bitwise_or.reduce(flags, axis=None, initial=0)) if flags is not None else 0
    if values.size == 0:
        return RoiMoments(0, 0, 0, np.nan, np.nan, flag).stats(name)
    q = _fixed(values)
    return RoiMoments(
        int(values.size),
        int(q.sum()),
        _exact_sum(q * q),
        float(values.min()),
        float(values.max()),
        flag,
    ).stats(name)


@dataclass(frozen=True, eq=False)
class RoiScan:
    """Where an ROI's pixels are on the depth grid, as :func:`scan_roi` visits them: the rows
    and columns of its box, a uint8 mask of the box (one row of ones: all of it) and the raw
    depth values it takes (inclusive; from 1 up: a depth range, whose rows are read only
    where their depth is in it)."""

    rows: slice
    cols: slice
    mask: NDArray[np.uint8]
    depth_units: tuple[int, int] = (0, 65535)

    @classmethod
    def of(cls, roi: Roi, shape: tuple[int, int], depth_scale_m: float) -> RoiScan:
        """The scan of ``roi`` on a depth image of ``shape`` (H, W): a rectangle is its box,
        a polygon its box and mask, a depth range the whole image and the raw depth values
        whose Z (float32 metres, as :attr:`~thermodepth.pipeline.FusedFrame.depth_m`) lies
        in it."""
        if isinstance(roi, DepthRangeRoi):
            units = np.arange(65536, dtype=np.uint16)
            z = units.astype(np.float32) * np.float32(depth_scale_m)
            inside = np.flatnonzero((units > 0) & (z >= roi.near_m) & (z <= roi.far_m))
            span = (int(inside[0]), int(inside[-1])) if inside.size else (1, 0)
            return cls(
                slice(0, shape[0]), slice(0, shape[1]), np.ones((1, shape[1]), np.uint8), span
            )
        mask = roi.mask(shape)
        rows, cols = bounding_box(mask)
        if isinstance(roi, RectRoi):
            return cls(rows, cols, np.ones((1, cols.stop - cols.start), np.uint8))
        return cls(rows, cols, np.ascontiguousarray(mask[rows, cols], np.uint8))


def scan_roi(
    scan: RoiScan,
    temp_c: NDArray[np.float32],
    depth: NDArray[np.uint16],
    thermal_index: NDArray[np.int32],
    thermal_flags: NDArray[np.int32],
) -> RoiMoments:
    """An ROI's exact moments over a fused frame: ``temp_c`` (H, W) float32 C (NaN: none),
    ``depth`` (H, W) raw units, ``thermal_index`` (H, W) the flat thermal pixel each depth
    pixel sees (-1: none) and ``thermal_flags`` (h * w) int32 those pixels' flags."""
    h = depth.shape[0]
    sums = np.zeros((h, 4), np.int64)
    keys = np.empty((h, 2), np.int32)  # rows outside the box: no extremes
    keys[:, 0], keys[:, 1] = _NO_MIN, _NO_MAX
    box = (scan.rows.start, scan.rows.stop, scan.cols.start, scan.cols.stop)
    lo, hi = (np.uint16(x) for x in scan.depth_units)  # compared with uint16 lanes
    gather = thermal_flags if thermal_flags.any() else thermal_flags[:0]  # none: no gathers
    _roi_rows(
        temp_c, temp_c.view(np.int32), depth, thermal_index, gather, box, scan.mask, lo, hi,
        sums, keys,
    )  # fmt: skip
    flags = int(np.bitwise_or.reduce(sums[:, 3]))
    n = int(sums[:, 0].sum())
    if n == 0:
        return RoiMoments(0, 0, 0, np.nan, np.nan, flags)
    extremes = np.array([keys[:, 0].min(), keys[:, 1].max()], np.int32)
    low, high = _key_flip(extremes).view(np.float32)
    return RoiMoments(
        n,
        int(sums[:, 1].sum()),
        _exact_sum(sums[:, 2]),
        float(low),
        float(high),
        flags,
    )


def _key_flip(keys: NDArray[np.int32]) -> NDArray[np.int32]:
    """float32 bits <-> integer keys in the floats' order (the map is its own inverse)."""
    return keys ^ ((keys >> 31) & np.int32(0x7FFFFFFF))


@numba.njit(parallel=True, fastmath=True, cache=True)
def _roi_rows(
    temp, bits, depth, index, flags, box, mask, lo, hi, sums, keys
):  # pragma: no cover - JIT
    # per row v of the box (v0, v1, u0, u1): the members are the pixels whose raw depth is in
    # lo..hi and whose mask is set (mask: the box's, or one row of ones that every row uses)
    # and that have a temperature. A depth range (lo > 0) first finds the span from the
    # first to the last pixel in range, on the depth alone, and reads only that. Into
    # sums[v]: n, sum q, sum q^2 and, when flags has any (flags.size > 0), the OR of the
    # flags of the thermal pixels that the ROI's pixels see (with a temperature or not);
    # into keys[v]: the extremes as order-preserving int32 keys of the float32 bits.
    # Integers only: the loops vectorize, and the totals do not depend on how the pixels
    # are split. Rows are sliced so that
    # indices start at 0 (no wraparound checks).
    v0, v1, u0, u1 = box
    limit = np.float32(_T_LIMIT_C)
    scale = np.float32(FIXED_POINT)
    half = np.float32(0.5)
    with_flags = flags.size > 0
    for v in numba.prange(v0, v1):
        drow = depth[v, u0:u1]
        a, b = 0, drow.size
        if lo > 0:
            first, last = np.int32(drow.size), np.int32(-1)
            for u in range(drow.size):
                inside = (drow[u] >= lo) & (drow[u] <= hi)
                first = min(first, np.int32(u) if inside else np.int32(drow.size))
                last = max(last, np.int32(u) if inside else np.int32(-1))
            a, b = first, max(last + 1, first)
        mrow = mask[v - v0 if mask.shape[0] > 1 else 0, a:b]
        d = drow[a:b]
        t = temp[v, u0 + a : u0 + b]
        bt = bits[v, u0 + a : u0 + b]
        n = np.int64(0)
        s = np.int64(0)
        s2 = np.int64(0)
        kmin, kmax = _NO_MIN, _NO_MAX
        for u in range(d.size):
            i = bt[u]
            ok = ((i & 0x7FFFFFFF) < 0x7F800000) & (d[u] >= lo) & (d[u] <= hi) & (mrow[u] != 0)
            x = np.floor(min(max(t[u], -limit), limit) * scale + half)
            q = np.int64(x) if ok else np.int64(0)
            n += np.int64(ok)
            s += q
            s2 += q * q
            key = i ^ ((i >> 31) & 0x7FFFFFFF)
            kmin = min(kmin, key if ok else _NO_MIN)
            kmax = max(kmax, key if ok else _NO_MAX)
        fl = np.int32(0)
        if with_flags:  # often none: then no gathers
            seen = index[v, u0 + a : u0 + b]
            for u in range(d.size):  # with or without a temperature: a flag says why not
                ok = (seen[u] >= 0) & (d[u] >= lo) & (d[u] <= hi) & (mrow[u] != 0)
                fl |= flags[max(seen[u], 0)] if ok else np.int32(0)
        sums[v, 0] = n
        sums[v, 1] = s
        sums[v, 2] = s2
        sums[v, 3] = fl
        keys[v, 0] = kmin
        keys[v, 1] = kmax


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
    area = 0.5 * np.linalg.norm(np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 1]), axis=-1)
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


# ---------------------------------------------------------------------------------------------
# Alarms
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class AlarmRule:
    """Raise when ``what`` is above ``above_c`` for ``for_frames`` frames in a row.

    what: ``"hotspot"`` (the hottest hotspot's max) or the name of an ROI (its max).
    """

    name: str
    above_c: float
    for_frames: int = 1
    what: str = "hotspot"

    def __post_init__(self) -> None:
        if self.for_frames < 1:
            raise ValueError(f"alarm {self.name!r}: for_frames must be >= 1, got {self.for_frames}")


@dataclass
class AlarmTracker:
    """Counts consecutive frames over each rule; emits an event when a rule trips and when
    it clears. A rule is active while its count reaches ``for_frames``. Events are plain
    dicts ready for JSON lines."""

    rules: Sequence[AlarmRule]
    counts: dict[str, int] = field(default_factory=dict)

    def update(
        self, time_s: float, frame_index: int, hotspots: Sequence[Hotspot], rois: Iterable[RoiStats]
    ) -> list[dict[str, Any]]:
        by_name = {r.name: r for r in rois}
        events = []
        for rule in self.rules:
            if rule.what == "hotspot":
                subject: Any = hotspots[0] if hotspots else None
                value = subject.max_c if subject else float("nan")
            else:
                subject = by_name.get(rule.what)
                value = subject.max_c if subject and subject.n else float("nan")
            over = bool(np.isfinite(value) and value > rule.above_c)
            count = self.counts.get(rule.name, 0)
            was_active = count >= rule.for_frames
            self.counts[rule.name] = count + 1 if over else 0
            if self.counts[rule.name] >= rule.for_frames and not was_active:
                events.append(_event("alarm", rule, time_s, frame_index, value, subject))
            elif not over and was_active:
                events.append(_event("clear", rule, time_s, frame_index, value, subject))
        return events


def _event(
    kind: str, rule: AlarmRule, time_s: float, frame_index: int, value: float, subject: Any
) -> dict[str, Any]:
    event: dict[str, Any] = {
        "event": kind,
        "rule": rule.name,
        "time_s": round(time_s, 4),
        "frame": frame_index,
        "above_c": rule.above_c,
        "for_frames": rule.for_frames,
        "value_c": None if not np.isfinite(value) else round(value, 3),
    }
    if isinstance(subject, Hotspot):
        event["hotspot"] = {
            k: v
            for k, v in subject.as_dict().items()
            if k in ("max_c", "mean_c", "centroid_m", "distance_m", "area_m2", "resolvable")
        }
    elif isinstance(subject, RoiStats):
        event["roi"] = subject.name
    return event


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
