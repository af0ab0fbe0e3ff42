"""Depth <-> thermal registration: which thermal pixel sees the surface of each depth pixel.

Two directions, on one calibration (``thermal_from_depth``, both intrinsics):

- :meth:`Registration.depth_to_thermal`: for every thermal pixel, the nearest surface among
  all depth pixels that land in it (a z-buffer): Z along the thermal optical axis and the
  Euclidean range (what the atmosphere model needs).
- :meth:`Registration.thermal_to_depth`: for every depth pixel, the thermal value of the
  pixel that sees it, NaN with a reason where the depth is invalid, the point falls outside
  the thermal image, or a nearer surface hides it from the thermal camera (the z-buffer
  test). librealsense's align has no such test, so hot objects bleed onto what is behind.

Methods (``REGISTRATION_METHODS``):

- ``"reproject"`` (default): every depth pixel is deprojected with its depth, moved into the
  thermal frame and projected through the thermal lens (OpenCV distortion, refused beyond the
  radius where the polynomial folds). Exact up to the depth noise.
- ``"paper"``: Lin & Yao 2022, sections 2.1-2.2: the thermal image is undistorted, then
  cropped/offset and upscaled to the depth grid with nearest neighbour: an affine map that is
  right at one reference distance only (parallax error elsewhere). No occlusion test.

Kernels are numba, multi-threaded over rows, float32 inside; compiled once and cached on
disk.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from pathlib import Path
from typing import Any, NamedTuple

import cv2
import numba
import numpy as np
from numpy.typing import NDArray

from .calibration import Calibration
from .camera import distort, pixel_rays

FloatArray = NDArray[np.float32]


class Reason(IntEnum):
    """Why a depth pixel has no thermal value (``ThermalOnDepth.reason``)."""

    OK = 0
    INVALID_DEPTH = 1
    OUTSIDE = 2
    OCCLUDED = 3


class DepthOnThermal(NamedTuple):
    """Nearest surface per thermal pixel, float32 (h, w), NaN where no depth pixel lands."""

    z_m: FloatArray
    range_m: FloatArray


class ThermalOnDepth(NamedTuple):
    """Thermal value per depth pixel, float32 (H, W) (NaN where none) and the reason, uint8."""

    values: FloatArray
    reason: NDArray[np.uint8]


# ---------------------------------------------------------------------------------------------
# kernels
# ---------------------------------------------------------------------------------------------

# fastmath without "reassoc": LLVM then may not reorder sums, so _project rounds the same in
# every kernel it is inlined into, and the z-buffer of depth_to_thermal, the one thermal_to_depth
# builds for itself and its sampling all agree on each pixel (with reassoc, 12 of 18.4 M pixels
# took another thermal pixel in one of two kernels; the speed is the same, measured).
_FASTMATH = {"nnan", "ninf", "nsz", "arcp", "contract", "afn"}
_JIT: dict[str, Any] = {"cache": True, "fastmath": _FASTMATH, "error_model": "numpy"}
# Those flags let LLVM assume no inf or NaN in float arithmetic ("nnan", "ninf": dropping them
# made the pipeline's sampling 4-9 % slower, measured), so the kernels compute with none: a
# thermal pixel that no point reaches has its nearest Z at the largest float32, not inf.
_FAR_M = np.float32(np.finfo(np.float32).max)

# geo (float32): t (3), fx, fy, cx, cy, k1, k2, p1, p2, k3, r2max, width, height of the
# thermal camera (the size as float32 too: comparing a float32 with an int goes through
# float64, measured 1.4x slower).
# Rays: the depth pixel (u, v) at depth z is the point P = R (z ray) + t = z (A_u + B_v) + t in
# the thermal frame, with per-column A (a0, a1, a2) and per-row B (brow); for a depth camera
# with distortion A holds a full (H, W) grid and B is zero.
#
# Each kernel runs its rows in one chunk per thread; inside a row, the projection is a loop
# of its own without branches (it vectorises), and the scatter or gather that follows is
# another: measured, this beats one fused loop by 3x.


@numba.njit(inline="always", **_JIT)
def _project(d, scale, a0, a1, a2, b0, b1, b2, geo):  # pragma: no cover - JIT
    # One depth pixel (d depth units; ray terms a + b) -> thermal (u, v), the point (x, y, z)
    # in the thermal frame and its nearest-pixel index: -1 invalid depth, -2 outside the
    # thermal image or the lens' valid radius.
    one = np.float32(1.0)
    two = np.float32(2.0)
    z = np.float32(d) * scale
    px = z * (a0 + b0) + geo[0]
    py = z * (a1 + b1) + geo[1]
    pz = z * (a2 + b2) + geo[2]
    inv = one / pz
    xn = px * inv
    yn = py * inv
    r2 = xn * xn + yn * yn
    radial = one + r2 * (geo[7] + r2 * (geo[8] + r2 * geo[11]))
    xy2 = two * xn * yn
    xd = xn * radial + geo[9] * xy2 + geo[10] * (r2 + two * xn * xn)
    yd = yn * radial + geo[9] * (r2 + two * yn * yn) + geo[10] * xy2
    uu = geo[3] * xd + geo[5]
    vv = geo[4] * yd + geo[6]
    fu = np.floor(uu + np.float32(0.5))
    fv = np.floor(vv + np.float32(0.5))
    inside = (pz > 0) & (r2 <= geo[12]) & (fu >= 0) & (fu < geo[13]) & (fv >= 0) & (fv < geo[14])
    i = np.int32(fv) * np.int32(geo[13]) + np.int32(fu)
    # plain conditionals compile to selects (a scalar np.where would allocate)
    idx = np.int32(-1) if d == 0 else (i if inside else np.int32(-2))
    return uu, vv, px, py, pz, idx


# The thermal camera sees only part of the depth image (56 of 89 deg here). On one depth
# row, the pixels that land in the thermal image at inverse depth w = 1/z form one interval,
# whose ends move monotonically with w (parallax). A table of those intervals over a grid of
# w, per row, bounds where any pixel of a row can land given the row's depth range: pixels
# outside that span are out of view without projecting them.
_W_STEP = 0.25  # 1/m: the table's grid of inverse depth, 0 .. 10 (z >= 0.1 m)
_W_SAMPLES = 41
_SPAN_MARGIN = 2  # pixels: float32 rounding and the curvature between grid points
_NOWHERE = 1 << 30  # a thermal row beyond any image: the bound of an empty set of rows


@numba.njit(parallel=True, **_JIT)
def _view_table(scale, a0, a1, a2, brow, geo, lo, hi, reach):  # pragma: no cover - JIT
    # lo[v, k], hi[v, k]: the depth pixels u of row v, lo <= u < hi, that land in the thermal
    # image at inverse depth w = k * _W_STEP (lo >= hi: none); reach[v, k]: the first and
    # last thermal rows they land in (first > last: none)
    h = brow.shape[0]
    w = a0.shape[1]
    w_t = np.int32(geo[13])
    for v in numba.prange(h):
        rv = min(np.int64(v), a0.shape[0] - 1)  # prange indices are unsigned
        b = brow[v]
        for k in range(lo.shape[1]):
            inv = max(k * _W_STEP, 1e-6)
            d = np.float32(1.0 / (inv * scale))  # the depth, in depth units
            first = w
            last = -1
            top = _NOWHERE
            bottom = -_NOWHERE
            for u in range(w):
                i = _project(d, scale, a0[rv, u], a1[rv, u], a2[rv, u], b[0], b[1], b[2], geo)[5]
                if i >= 0:
                    first = min(first, u)
                    last = max(last, u)
                    top = min(top, i // w_t)
                    bottom = max(bottom, i // w_t)
            lo[v, k] = first
            hi[v, k] = last + 1
            reach[v, k, 0] = top
            reach[v, k, 1] = bottom


@numba.njit(inline="always", **_JIT)
def _row_span(drow, scale, lo_row, hi_row):  # pragma: no cover - JIT
    # [u0, u1): where this row's pixels can land in the thermal image, given its depth range,
    # and [k0, k1]: the table's grid points of inverse depth around that range (k0 > k1: no
    # valid depth; k1 off the table: nearer than it reaches, and [u0, u1) the whole row)
    w = drow.size
    dmin = np.uint16(65535)
    dmax = np.uint16(0)
    for u in range(w):
        d = drow[u]
        dmin = min(dmin, d if d > 0 else np.uint16(65535))
        dmax = max(dmax, d)
    if dmax == 0:
        return 0, 0, 1, 0
    w_lo = 1.0 / (np.float32(dmax) * scale)
    w_hi = 1.0 / (np.float32(dmin) * scale)
    k0 = int(np.floor(w_lo / _W_STEP))
    k1 = int(np.ceil(w_hi / _W_STEP))
    if k1 >= lo_row.size:
        return 0, w, k0, k1  # look at everything
    u0 = w
    u1 = 0
    for k in range(k0, k1 + 1):
        if lo_row[k] < hi_row[k]:
            u0 = min(u0, lo_row[k])
            u1 = max(u1, hi_row[k])
    if u0 >= u1:
        return 0, 0, k0, k1
    return max(u0 - _SPAN_MARGIN, 0), min(u1 + _SPAN_MARGIN, w), k0, k1


@numba.njit(inline="always", **_JIT)
def _row_reach(reach_row, k0, k1):  # pragma: no cover - JIT
    # the first and last thermal rows a depth row can land in between grid points k0 and k1
    # (first > last: none; k1 off the table: anywhere)
    if k1 >= reach_row.shape[0]:
        return -_NOWHERE, _NOWHERE
    top = _NOWHERE
    bottom = -_NOWHERE
    for k in range(k0, k1 + 1):
        if reach_row[k, 0] <= reach_row[k, 1]:
            top = min(top, reach_row[k, 0])
            bottom = max(bottom, reach_row[k, 1])
    return top, bottom


_REACH_SLACK = 1  # thermal rows: a pixel's row between the table's grid points, and rounding


def _sampling_lag(reach: NDArray[np.int32]) -> int:
    """Depth rows: how far apart two depth rows can be and still meet in the z-buffer, one
    landing in a thermal row that the other samples (its nearest pixel's row or, bilinear,
    the row above or below), at any depth the view table covers. reach (H, K, 2): the first
    and last thermal row of each depth row at each of the table's depths (:func:`_view_table`).
    """
    top, bottom = reach[:, :, 0].min(axis=1), reach[:, :, 1].max(axis=1)
    rows = np.flatnonzero(top <= bottom)
    if rows.size == 0:
        return 0
    top, bottom = top[rows], bottom[rows]
    gap = 2 * _REACH_SLACK + 1
    meet = (top[None, :] - bottom[:, None] <= gap) & (top[:, None] - bottom[None, :] <= gap)
    return int(np.abs(rows[:, None] - rows[None, :])[meet].max())


_SCATTER_STRIDE = 8  # depth pixels: more than one thermal pixel spans (~4 on the D435 + Lepton)


@numba.njit(inline="always", **_JIT)
def _scatter_min(idx, values, buf, n):  # pragma: no cover - JIT
    # buf[idx[u]] = min(buf[idx[u]], values[u]) for u < n where idx[u] >= 0. Neighbouring
    # depth pixels share a thermal pixel: in order, each min would wait for the store of the
    # one before (store-to-load forwarding). _SCATTER_STRIDE apart they land in different
    # thermal pixels and the updates overlap (measured 1.17x faster on one thread, 1.04-1.11x
    # on two).
    for s in range(_SCATTER_STRIDE):
        for m in range((n - s + _SCATTER_STRIDE - 1) // _SCATTER_STRIDE):
            u = m * _SCATTER_STRIDE + s
            i = idx[u]
            if i >= 0:
                buf[i] = min(buf[i], values[u])


# The z-buffer keeps, per thermal pixel, one uint64 key: the float32 bits of Z above those of
# the range. Positive floats order as their bits, so the nearest point is the smallest key, and
# one branch-free min per pixel updates both (a compare-and-branch on noisy Z mispredicts:
# measured 1.7x slower). The empty key decodes to Z = inf, range = NaN.
_EMPTY_KEY = np.uint64(0x7F800000_7FC00000)


@numba.njit(parallel=True, **_JIT)
def _zbuffer(depth, scale, a0, a1, a2, brow, geo, lo, hi, keys):  # pragma: no cover - JIT
    # keys (n_chunks, h_t * w_t): each chunk of rows fills its own; merged into keys[0]
    h, w = depth.shape
    n_chunks = keys.shape[0]
    for k in numba.prange(n_chunks):
        kloc = keys[k]
        kloc[:] = _EMPTY_KEY
        zt = np.empty(w, np.float32)
        rt = np.empty(w, np.float32)
        idx = np.empty(w, np.int32)
        key = np.empty(w, np.uint64)
        zbits = zt.view(np.uint32)
        rbits = rt.view(np.uint32)
        for v in range(k * h // n_chunks, (k + 1) * h // n_chunks):
            rv = min(v, a0.shape[0] - 1)
            drow, ar0, ar1, ar2 = depth[v], a0[rv], a1[rv], a2[rv]
            b0, b1, b2 = brow[v, 0], brow[v, 1], brow[v, 2]
            u0, u1, _, _ = _row_span(drow, scale, lo[v], hi[v])
            # loops over views that start at 0: a non-zero range start would make numba
            # check every index for wraparound, which stops vectorisation (4x slower)
            dr, c0, c1, c2 = drow[u0:u1], ar0[u0:u1], ar1[u0:u1], ar2[u0:u1]
            n = dr.size
            for u in range(n):
                _, _, px, py, pz, i = _project(dr[u], scale, c0[u], c1[u], c2[u], b0, b1, b2, geo)
                zt[u] = pz
                rt[u] = np.sqrt(px * px + py * py + pz * pz)
                idx[u] = i
            for u in range(n):
                key[u] = (np.uint64(zbits[u]) << np.uint64(32)) | np.uint64(rbits[u])
            _scatter_min(idx, key, kloc, n)
    for i in range(keys.shape[1]):  # serial: 19,200 compares cost less than waking threads
        for k in range(1, n_chunks):
            keys[0, i] = min(keys[0, i], keys[k, i])


@numba.njit(parallel=True, **_JIT)
def _sample(
    depth,
    scale,
    a0,
    a1,
    a2,
    brow,
    geo,
    lo,
    hi,
    reach,
    values,
    nearest_z,
    build,
    lag,
    tol_sigma,
    tol_slope,
    bilinear,
    n_chunks,
    out,
    reason,
    want_index,
    index,
    near,
):  # pragma: no cover - JIT
    # values, nearest_z (h_t * w_t): each thermal pixel's value and the Z of its nearest
    # surface (_FAR_M: none). build: nearest_z is yet to fill (all _FAR_M). Each chunk of rows
    # then fills a copy of its own, in one pass: it projects its rows, and the rows around
    # them that can land in a thermal pixel its rows sample, in order, each once, into a ring
    # of lag + 1 rows (`lag`: the farthest apart two rows can meet, _sampling_lag), and samples
    # a row as soon as no row still to project can land in the thermal rows it samples (reach:
    # the view table's thermal rows per depth row and grid point). One parallel region and one
    # projection per pixel, where building the whole z-buffer first takes two of each.
    # near[k] = 1: a row chunk k looked at has depth nearer than the view table reaches; its
    # pixels can land anywhere, so the caller must build the whole z-buffer and call again.
    # index (H, W) gets the flat thermal index each depth pixel took (-1: none) if want_index.
    h, w = depth.shape
    nan = np.float32(np.nan)
    lag = lag if build else 0
    ring = lag + 1
    gap = 2 * _REACH_SLACK + 1  # thermal rows: two rows' slack and the bilinear neighbour
    for k in numba.prange(n_chunks):
        first = k * h // n_chunks
        end = (k + 1) * h // n_chunks
        if first == end:  # more chunks than rows
            continue
        zbuf = nearest_z.copy() if build else nearest_z
        n_uv = ring if bilinear else 1
        ut = np.empty((n_uv, w), np.float32)
        vt = np.empty((n_uv, w), np.float32)
        zt = np.empty((ring, w), np.float32)
        idx = np.empty((ring, w), np.int32)
        val = np.empty(w, np.float32)
        near_z = np.empty(w, np.float32)
        # the window, all rows that can meet the chunk's: each row's span and the thermal rows
        # it can land in at its depths; later[i]: the first thermal row that any row from
        # w0 + i on can land in
        w0 = max(first - lag, 0)
        w1 = min(end + lag, h)
        spans = np.empty((w1 - w0, 2), np.int64)
        tops = np.empty(w1 - w0, np.int64)
        bottoms = np.empty(w1 - w0, np.int64)
        for p in range(w0, w1):
            u0, u1, k0, k1 = _row_span(depth[p], scale, lo[p], hi[p])
            if build and k1 >= lo.shape[1]:
                near[k] = 1
            spans[p - w0, 0] = u0
            spans[p - w0, 1] = u1
            tops[p - w0], bottoms[p - w0] = _row_reach(reach[p], k0, k1)
        later = np.empty(w1 - w0 + 1, np.int64)
        later[w1 - w0] = _NOWHERE
        for i in range(w1 - w0 - 1, -1, -1):
            later[i] = min(later[i + 1], tops[i])
        # start at the first row above the chunk that can meet it
        top = tops[first - w0 : end - w0].min()
        bottom = bottoms[first - w0 : end - w0].max()
        start = first
        for p in range(w0, first):
            if bottoms[p - w0] + gap >= top and tops[p - w0] - gap <= bottom:
                start = p
                break
        v = first  # the next row to sample
        p = start  # the next row to project
        while v < end:
            if p < w1:  # project row p into the ring (and the z-buffer)
                slot = p % ring
                uv = slot if bilinear else 0
                rp = min(p, a0.shape[0] - 1)
                u0, u1 = spans[p - w0, 0], spans[p - w0, 1]
                b0, b1, b2 = brow[p, 0], brow[p, 1], brow[p, 2]
                # loops over views that start at 0 (see _zbuffer)
                dr, c0, c1, c2 = depth[p, u0:u1], a0[rp, u0:u1], a1[rp, u0:u1], a2[rp, u0:u1]
                ur, vr, zr, ir = ut[uv], vt[uv], zt[slot], idx[slot]
                if bilinear:  # nearest needs no (u, v): not storing them is 3-4 % faster
                    for u in range(dr.size):
                        ur[u], vr[u], _, _, zr[u], ir[u] = _project(
                            dr[u], scale, c0[u], c1[u], c2[u], b0, b1, b2, geo
                        )
                else:
                    for u in range(dr.size):
                        _, _, _, _, zr[u], ir[u] = _project(
                            dr[u], scale, c0[u], c1[u], c2[u], b0, b1, b2, geo
                        )
                if build:
                    _scatter_min(ir, zr, zbuf, dr.size)
                p += 1
            # sample the rows that no row still to project can reach; past the lag, none can
            while v < min(p, end) and (
                p == w1 or p - v > lag or later[p - w0] - gap > bottoms[v - w0]
            ):
                slot = v % ring
                u0, u1 = spans[v - w0, 0], spans[v - w0, 1]
                drow = depth[v]
                # outside the span: invalid depth, or out of the thermal view
                _fill_outside(drow[:u0], out[v, :u0], reason[v, :u0])
                _fill_outside(drow[u1:], out[v, u1:], reason[v, u1:])
                orow, rrow = out[v, u0:u1], reason[v, u0:u1]
                zr, ir = zt[slot], idx[slot]
                n = u1 - u0
                for u in range(n):
                    j = max(ir[u], np.int32(0))
                    val[u] = values[j]
                    near_z[u] = zbuf[j]
                for u in range(n):
                    i = ir[u]
                    pz = zr[u]
                    # hidden when the thermal pixel's nearest surface is clearly in front: beyond
                    # the depth noise (sigma ~ z^2) and the spread of a slanted surface in a pixel
                    tol = tol_sigma * pz * pz + tol_slope * pz
                    occluded = (i >= 0) & (pz > near_z[u] + tol)
                    orow[u] = val[u] if (i >= 0) & ~occluded else nan
                    rrow[u] = np.uint8(
                        np.int32(i == -1) * Reason.INVALID_DEPTH
                        + np.int32(i == -2) * Reason.OUTSIDE
                        + np.int32(occluded) * Reason.OCCLUDED
                    )
                if bilinear:
                    _bilinear_row(
                        ut[slot][:n],
                        vt[slot][:n],
                        zr[:n],
                        rrow,
                        orow,
                        values,
                        zbuf,
                        geo,
                        tol_sigma,
                        tol_slope,
                    )
                if want_index:
                    irow = index[v]
                    irow[:u0] = -1
                    irow[u1:] = -1
                    iin = irow[u0:u1]
                    for u in range(n):
                        iin[u] = ir[u] if rrow[u] == Reason.OK else -1
                v += 1


@numba.njit(inline="always", **_JIT)
def _fill_outside(drow, orow, rrow):  # pragma: no cover - JIT
    nan = np.float32(np.nan)
    for u in range(drow.size):
        orow[u] = nan
        rrow[u] = Reason.INVALID_DEPTH if drow[u] == 0 else Reason.OUTSIDE


@numba.njit(inline="always", **_JIT)
def _bilinear_row(
    ut, vt, zt, rrow, orow, values, zbuf, geo, tol_sigma, tol_slope
):  # pragma: no cover
    # bilinear over the neighbours that see the same surface as the depth pixel
    w_t, h_t = int(geo[13]), int(geo[14])
    for u in range(ut.size):
        if rrow[u] != 0:
            continue
        pz = zt[u]
        tol = tol_sigma * pz * pz + tol_slope * pz
        u0 = int(np.floor(ut[u]))
        v0 = int(np.floor(vt[u]))
        fu = ut[u] - np.float32(u0)
        fv = vt[u] - np.float32(v0)
        acc = np.float32(0.0)
        wsum = np.float32(0.0)
        for dv in range(2):
            for du in range(2):
                uu = min(max(u0 + du, 0), w_t - 1)
                vv = min(max(v0 + dv, 0), h_t - 1)
                wgt = (fu if du else np.float32(1.0) - fu) * (fv if dv else np.float32(1.0) - fv)
                j = vv * w_t + uu
                if wgt > 0 and pz <= zbuf[j] + tol:
                    acc += wgt * values[j]
                    wsum += wgt
        if wsum > 0:
            orow[u] = acc / wsum


# ---------------------------------------------------------------------------------------------
# the Registration object
# ---------------------------------------------------------------------------------------------

REGISTRATION_METHODS = ("reproject", "paper")


@dataclass(frozen=True)
class OcclusionTolerance:
    """How much farther than the thermal pixel's nearest surface a point may be and still be
    seen: n_sigma * sigma_z(z) + slope * z / fx_thermal.

    sigma_z = z^2 subpixel / (fx_depth baseline) is the depth camera's noise model (D435:
    subpixel 0.08, baseline 50 mm). The z-buffer keeps the minimum of ~20 noisy samples per
    thermal pixel, so a point of the same surface can lie ~5 sigma behind it: n_sigma = 6.
    slope = 2 lets surfaces slanted up to ~63 deg to the thermal ray spread their depth
    across a thermal pixel without hiding themselves.
    """

    n_sigma: float = 6.0
    subpixel: float = 0.08
    stereo_baseline_m: float = 0.050
    slope: float = 2.0

    def coefficients(self, calibration: Calibration) -> tuple[float, float]:
        """(a, b) of the tolerance a z^2 + b z (metres, z in metres) for a calibration."""
        fx_depth, fx_thermal = calibration.depth.fx, calibration.thermal.fx
        return (
            self.n_sigma * self.subpixel / (fx_depth * self.stereo_baseline_m),
            self.slope / fx_thermal,
        )


class Registration:
    """Maps between the depth grid (H, W) and the thermal grid (h, w) of one calibration.

    method: ``"reproject"`` (exact, occlusion-aware; default) or ``"paper"`` (the paper's
    nearest-neighbour upscale, fitted at ``paper_reference_m``).
    """

    def __init__(
        self,
        calibration: Calibration,
        method: str = "reproject",
        tolerance: OcclusionTolerance | None = None,
        paper_reference_m: float = 1.5,
    ) -> None:
        if method not in REGISTRATION_METHODS:
            raise ValueError(
                f"unknown registration method {method!r}; choose from {list(REGISTRATION_METHODS)}"
            )
        self.calibration = calibration
        self.method = method
        self.tolerance = tolerance or OcclusionTolerance()
        self.paper_reference_m = paper_reference_m
        t = calibration.thermal
        if method == "paper":
            self._paper = _PaperMaps.fit(calibration, paper_reference_m)
            return
        self._scale = np.float32(calibration.depth_scale_m)
        self._rays = _ray_terms(calibration)
        tr = calibration.thermal_from_depth.translation_m
        self._geo = np.array(
            [
                *tr,
                t.fx,
                t.fy,
                t.cx,
                t.cy,
                *t.distortion,
                min(t.max_radius2, 1e30),
                t.width,
                t.height,
            ],
            dtype=np.float32,
        )
        self._tol_sigma, self._tol_slope = map(np.float32, self.tolerance.coefficients(calibration))
        self._n_chunks = max(1, numba.get_num_threads())
        self._span_lo = np.empty((calibration.depth.height, _W_SAMPLES), dtype=np.int32)
        self._span_hi = np.empty_like(self._span_lo)
        self._reach = np.empty((*self._span_lo.shape, 2), dtype=np.int32)
        _view_table(self._scale, *self._rays, self._geo, self._span_lo, self._span_hi, self._reach)
        self._lag = _sampling_lag(self._reach)

    @classmethod
    def from_file(
        cls, path: str | Path, method: str = "reproject", **kwargs: object
    ) -> Registration:
        """Registration from a calibration file (YAML or JSON)."""
        return cls(Calibration.load(path), method, **kwargs)  # type: ignore[arg-type]

    # -- checks ------------------------------------------------------------------------------

    def _check_depth(self, depth: NDArray[np.uint16]) -> NDArray[np.uint16]:
        shape = self.calibration.depth.shape
        if not isinstance(depth, np.ndarray) or depth.dtype != np.uint16 or depth.shape != shape:
            raise ValueError(
                f"depth must be a uint16 array of shape {shape} (H, W) in depth "
                f"units, got {_describe(depth)}"
            )
        return np.ascontiguousarray(depth)

    def _check_thermal(self, thermal: NDArray[np.generic]) -> FloatArray:
        shape = self.calibration.thermal.shape
        if (
            not isinstance(thermal, np.ndarray)
            or thermal.shape != shape
            or thermal.dtype.kind not in "uif"
        ):
            raise ValueError(
                f"thermal must be a numeric array of shape {shape} (h, w) "
                f"(uint16 counts or float), got {_describe(thermal)}"
            )
        return np.ascontiguousarray(thermal, dtype=np.float32)

    # -- depth -> thermal --------------------------------------------------------------------

    def _zbuffer(self, depth: NDArray[np.uint16]) -> tuple[FloatArray, FloatArray]:
        """Nearest Z per thermal pixel and that point's range, flat (h * w) views, inf / NaN
        where no depth pixel lands."""
        h_t, w_t = self.calibration.thermal.shape
        keys = np.empty((self._n_chunks, h_t * w_t), dtype=np.uint64)
        _zbuffer(
            depth,
            self._scale,
            *self._rays,
            self._geo,
            self._span_lo,
            self._span_hi,
            keys,
        )
        halves = keys[0].view(np.float32)  # little-endian: range, then Z
        return halves[1::2], halves[0::2]

    def depth_to_thermal(self, depth: NDArray[np.uint16]) -> DepthOnThermal:
        """Distance of the nearest surface seen by each thermal pixel.

        depth: (H, W) uint16 in depth units (0 = invalid). Returns float32 (h, w) arrays:
        Z along the thermal optical axis and the range (metres), NaN where no depth pixel
        lands. ``"paper"``: the depth pixel the upscale maps to each thermal pixel's centre
        (Z and range in the depth camera's frame).
        """
        depth = self._check_depth(depth)
        if self.method == "paper":
            return self._paper.depth_to_thermal(depth)
        zbuf, rbuf = self._zbuffer(depth)
        shape = self.calibration.thermal.shape
        z_m = np.where(np.isfinite(zbuf), zbuf, np.float32(np.nan)).reshape(shape)
        return DepthOnThermal(z_m, np.ascontiguousarray(rbuf).reshape(shape))

    # -- thermal -> depth --------------------------------------------------------------------

    def thermal_to_depth(
        self,
        depth: NDArray[np.uint16],
        thermal: NDArray[np.generic],
        interpolation: str = "nearest",
        nearest: DepthOnThermal | None = None,
        thermal_index: NDArray[np.int32] | None = None,
    ) -> ThermalOnDepth:
        """The thermal value seen at every depth pixel.

        depth: (H, W) uint16 depth units; thermal: (h, w) counts (uint16) or float (e.g.
        temperatures). interpolation: ``"nearest"`` or ``"bilinear"`` (over the neighbours
        that see the same surface). nearest: :meth:`depth_to_thermal` of this same depth
        frame, if already computed: its Z is the z-buffer of the occlusion test, which is
        then not computed again. thermal_index: an int32 (H, W) array to fill with the flat
        index (v * w + u) of the thermal pixel each depth pixel sees (the nearest one), -1
        where ``reason != Reason.OK``, so other thermal-grid data (flags) can follow without
        a second pass. Returns float32 (H, W) values, NaN where ``reason != Reason.OK``
        (invalid depth, outside the thermal image, occluded).
        """
        depth = self._check_depth(depth)
        therm = self._check_thermal(thermal)
        if interpolation not in ("nearest", "bilinear"):
            raise ValueError(
                f"interpolation must be 'nearest' or 'bilinear', got {interpolation!r}"
            )
        if thermal_index is not None and (
            thermal_index.shape != depth.shape
            or thermal_index.dtype != np.int32
            or not thermal_index.flags.c_contiguous
        ):
            raise ValueError(
                f"thermal_index must be a C-contiguous int32 array of shape {depth.shape}, "
                f"got {_describe(thermal_index)}"
            )
        if self.method == "paper":
            return self._paper.thermal_to_depth(depth, therm, interpolation, thermal_index)
        if nearest is None:  # the sampling kernel builds its own z-buffer
            zbuf = np.full(therm.size, _FAR_M, dtype=np.float32)
        else:
            zbuf = np.where(np.isnan(nearest.z_m), _FAR_M, nearest.z_m).ravel()
        out = np.empty(depth.shape, dtype=np.float32)
        reason = np.empty(depth.shape, dtype=np.uint8)
        near = np.zeros(self._n_chunks, dtype=np.uint8)
        index = thermal_index if thermal_index is not None else np.empty((1, 1), np.int32)

        def sample(zbuf: FloatArray, build: bool) -> None:
            _sample(
                depth,
                self._scale,
                *self._rays,
                self._geo,
                self._span_lo,
                self._span_hi,
                self._reach,
                therm.ravel(),
                zbuf,
                build,
                self._lag,
                self._tol_sigma,
                self._tol_slope,
                interpolation == "bilinear",
                self._n_chunks,
                out,
                reason,
                thermal_index is not None,
                index,
                near,
            )

        sample(zbuf, nearest is None)
        if near.any():
            # depth nearer than the view table reaches: those pixels can land in any thermal
            # row, beyond the lag rows a chunk takes in, so build the whole z-buffer first
            sample(np.minimum(self._zbuffer(depth)[0], _FAR_M), False)
        return ThermalOnDepth(out, reason)

    # -- the paper's method ------------------------------------------------------------------

    def thermal_pixel_of_depth(self) -> tuple[FloatArray, FloatArray]:
        """``"paper"``: the raw thermal (u, v) each depth pixel samples, float32 (H, W) each."""
        return self._paper.map_u, self._paper.map_v


class _PaperMaps:
    """The paper's registration (section 2.2) as fixed lookups: a crop/offset + upscale from
    depth pixels to undistorted thermal pixels, u_t = a_u u + b_u, v_t = a_v v + b_v. All
    that does not depend on the frame is computed here, once."""

    def __init__(self, cal: Calibration, affine: tuple[float, float, float, float]) -> None:
        d, t = cal.depth, cal.thermal
        a_u, b_u, a_v, b_v = affine
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

    @classmethod
    def fit(cls, cal: Calibration, distance_m: float) -> _PaperMaps:
        """The maps with the affine fitted (least squares) to the exact mapping of a plane at
        ``distance_m`` (the paper sets it by hand at its working distance)."""
        d, t = cal.depth, cal.thermal
        u, v = d.pixel_grid()
        uu, vv = u[::8, ::8], v[::8, ::8]
        pts = cal.thermal_from_depth.apply(d.deproject(np.stack([uu, vv], -1), distance_m))
        x, y = pts[..., 0] / pts[..., 2], pts[..., 1] / pts[..., 2]
        und_u, und_v = t.fx * x + t.cx, t.fy * y + t.cy
        ok = t.contains(np.stack([und_u, und_v], axis=-1))
        a_u, b_u = np.polyfit(uu[ok], und_u[ok], 1)
        a_v, b_v = np.polyfit(vv[ok], und_v[ok], 1)
        return cls(cal, (float(a_u), float(b_u), float(a_v), float(b_v)))

    def thermal_to_depth(
        self,
        depth: NDArray[np.uint16],
        therm: FloatArray,
        interpolation: str,
        thermal_index: NDArray[np.int32] | None,
    ) -> ThermalOnDepth:
        """See :meth:`Registration.thermal_to_depth` (no occlusion test: the paper has none)."""
        flag = cv2.INTER_NEAREST if interpolation == "nearest" else cv2.INTER_LINEAR
        out = cv2.remap(
            therm, self.map_u, self.map_v, flag, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan
        )
        valid = depth != 0
        reason = np.where(
            valid, np.where(self.inside, Reason.OK, Reason.OUTSIDE), Reason.INVALID_DEPTH
        ).astype(np.uint8)
        ok = valid & self.inside
        out[~ok] = np.nan
        if thermal_index is not None:
            np.copyto(thermal_index, np.where(ok, self.index, np.int32(-1)))
        return ThermalOnDepth(np.asarray(out, dtype=np.float32), reason)

    def depth_to_thermal(self, depth: NDArray[np.uint16]) -> DepthOnThermal:
        """See :meth:`Registration.depth_to_thermal`: Z (and range) in the depth camera's
        frame of the depth pixel under each thermal pixel's centre."""
        units = np.where(self.seen, depth.ravel()[self.source], 0)
        z = np.where(units > 0, units * self.scale, np.float32(np.nan)).astype(np.float32)
        return DepthOnThermal(z, z * self.range_per_z)


def _describe(a: object) -> str:
    """An array's dtype and shape (or the type of what is not an array), for messages."""
    return f"{a.dtype} {a.shape}" if isinstance(a, np.ndarray) else type(a).__name__


def _ray_terms(cal: Calibration) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Per-column (a0, a1, a2) and per-row (brow, (H, 3)) terms of R @ ray, float32.

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
        return a[0], a[1], a[2], np.ascontiguousarray(b, dtype=np.float32)
    x, y = pixel_rays(d)
    a = [
        np.ascontiguousarray(x * rot[i, 0] + y * rot[i, 1] + rot[i, 2], dtype=np.float32)
        for i in range(3)
    ]
    return a[0], a[1], a[2], np.zeros((d.height, 3), dtype=np.float32)
