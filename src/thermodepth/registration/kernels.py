"""The registration's numba kernels: projection of depth pixels through the thermal lens, the
view table, the z-buffer and the one-pass occlusion-tested sampling.

Multi-threaded over rows, float32 inside, compiled once and cached on disk. Their inputs are
grouped in named tuples (:class:`Lens`, :class:`Rays`, :class:`ViewTable`, :class:`Sampling`,
:class:`Sampled`) that numba passes by value, as fast as loose arguments.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numba
import numpy as np
from numpy.typing import NDArray

from .base import Reason

# fastmath without "reassoc": LLVM then may not reorder sums, so _project rounds the same in
# every kernel it is inlined into, and the z-buffer of depth_to_thermal, the one thermal_to_depth
# builds for itself and its sampling all agree on each pixel (with reassoc, 12 of 18.4 M pixels
# took another thermal pixel in one of two kernels; the speed is the same, measured).
_FASTMATH = {"nnan", "ninf", "nsz", "arcp", "contract", "afn"}
_JIT: dict[str, Any] = {"cache": True, "fastmath": _FASTMATH, "error_model": "numpy"}
# Those flags let LLVM assume no inf or NaN in float arithmetic ("nnan", "ninf": dropping them
# made the pipeline's sampling 4-9 % slower, measured), so the kernels compute with none: a
# thermal pixel that no point reaches has its nearest Z at the largest float32, not inf.
FAR_M = np.float32(np.finfo(np.float32).max)


class Lens(NamedTuple):
    """The thermal camera as the kernels see it, all float32: the translation of
    ``thermal_from_depth`` (m), the intrinsics (px), the distortion [k1, k2, p1, p2, k3], the
    squared radius beyond which the distortion polynomial folds, and the image size (as float32
    too: comparing a float32 with an int goes through float64, measured 1.4x slower)."""

    tx: np.float32
    ty: np.float32
    tz: np.float32
    fx: np.float32
    fy: np.float32
    cx: np.float32
    cy: np.float32
    k1: np.float32
    k2: np.float32
    p1: np.float32
    p2: np.float32
    k3: np.float32
    r2max: np.float32
    width: np.float32
    height: np.float32


class Rays(NamedTuple):
    """R @ ray of every depth pixel, float32, split so that most cameras need no grid: the
    depth pixel (u, v) at depth z is the point P = z (A_u + B_v) + t in the thermal frame,
    with per-column A = (a0, a1, a2), each (1, W), and per-row B = brow (H, 3); for a depth
    camera with distortion A holds a full (H, W) grid and B is zero."""

    a0: NDArray[np.float32]
    a1: NDArray[np.float32]
    a2: NDArray[np.float32]
    brow: NDArray[np.float32]


class ViewTable(NamedTuple):
    """Where each depth row can land, by inverse depth (:func:`view_table`): ``lo``, ``hi``
    (H, K) int32, the depth pixels lo <= u < hi of the row that land in the thermal image at
    w = k * _W_STEP; ``reach`` (H, K, 2) int32, the first and last thermal rows they land in."""

    lo: NDArray[np.int32]
    hi: NDArray[np.int32]
    reach: NDArray[np.int32]


class Sampling(NamedTuple):
    """How :func:`sample` samples: ``lag`` (depth rows two rows can be apart and still meet in
    the z-buffer), the occlusion tolerance ``tol_sigma`` z^2 + ``tol_slope`` z (float32),
    ``bilinear`` (else nearest), ``n_chunks`` (row chunks, one per thread)."""

    lag: int
    tol_sigma: np.float32
    tol_slope: np.float32
    bilinear: bool
    n_chunks: int


class Sampled(NamedTuple):
    """What :func:`sample` fills: ``values`` (H, W) float32, ``reason`` (H, W) uint8 and, when
    ``want_index``, ``thermal_index`` (H, W) int32; ``near`` (n_chunks,) uint8 marks row
    chunks with depth nearer than the view table reaches."""

    values: NDArray[np.float32]
    reason: NDArray[np.uint8]
    thermal_index: NDArray[np.int32]
    want_index: bool
    near: NDArray[np.uint8]


# Rays: the depth pixel (u, v) at depth z is the point P = R (z ray) + t = z (A_u + B_v) + t in
# the thermal frame, with per-column A (a0, a1, a2) and per-row B (brow); for a depth camera
# with distortion A holds a full (H, W) grid and B is zero.
#
# Each kernel runs its rows in one chunk per thread; inside a row, the projection is a loop
# of its own without branches (it vectorises), and the scatter or gather that follows is
# another: measured, this beats one fused loop by 3x.


@numba.njit(inline="always", **_JIT)
def _project(d, scale, a0, a1, a2, b0, b1, b2, lens):  # pragma: no cover - JIT
    # One depth pixel (d depth units; ray terms a + b) -> thermal (u, v), the point (x, y, z)
    # in the thermal frame and its nearest-pixel index: -1 invalid depth, -2 outside the
    # thermal image or the lens' valid radius.
    one = np.float32(1.0)
    two = np.float32(2.0)
    z = np.float32(d) * scale
    px = z * (a0 + b0) + lens.tx
    py = z * (a1 + b1) + lens.ty
    pz = z * (a2 + b2) + lens.tz
    inv = one / pz
    xn = px * inv
    yn = py * inv
    r2 = xn * xn + yn * yn
    radial = one + r2 * (lens.k1 + r2 * (lens.k2 + r2 * lens.k3))
    xy2 = two * xn * yn
    xd = xn * radial + lens.p1 * xy2 + lens.p2 * (r2 + two * xn * xn)
    yd = yn * radial + lens.p1 * (r2 + two * yn * yn) + lens.p2 * xy2
    uu = lens.fx * xd + lens.cx
    vv = lens.fy * yd + lens.cy
    fu = np.floor(uu + np.float32(0.5))
    fv = np.floor(vv + np.float32(0.5))
    inside = (
        (pz > 0)
        & (r2 <= lens.r2max)
        & (fu >= 0)
        & (fu < lens.width)
        & (fv >= 0)
        & (fv < lens.height)
    )
    i = np.int32(fv) * np.int32(lens.width) + np.int32(fu)
    # plain conditionals compile to selects (a scalar np.where would allocate)
    idx = np.int32(-1) if d == 0 else (i if inside else np.int32(-2))
    return uu, vv, px, py, pz, idx


@numba.njit(inline="always", **_JIT)
def project_point(x, y, z, lens):  # pragma: no cover - JIT
    # A point (x, y, z) in the camera's own frame (a lens of zero translation) -> (u, v), z
    # and its nearest-pixel index (-2 outside the image or the lens' valid radius): the same
    # rounding as every depth pixel's, for the map's voxels and vertices.
    one = np.float32(1.0)
    zero = np.float32(0.0)
    uu, vv, _, _, pz, idx = _project(one, one, x, y, z, zero, zero, zero, lens)
    return uu, vv, pz, idx


# The thermal camera sees only part of the depth image (56 of 89 deg here). On one depth
# row, the pixels that land in the thermal image at inverse depth w = 1/z form one interval,
# whose ends move monotonically with w (parallax). A table of those intervals over a grid of
# w, per row, bounds where any pixel of a row can land given the row's depth range: pixels
# outside that span are out of view without projecting them.
_W_STEP = 0.25  # 1/m: the table's grid of inverse depth, 0 .. 10 (z >= 0.1 m)
W_SAMPLES = 41
_SPAN_MARGIN = 2  # pixels: float32 rounding and the curvature between grid points
_NOWHERE = 1 << 30  # a thermal row beyond any image: the bound of an empty set of rows


@numba.njit(parallel=True, **_JIT)
def view_table(scale, rays, lens, view):  # pragma: no cover - JIT
    # view.lo[v, k], view.hi[v, k]: the depth pixels u of row v, lo <= u < hi, that land in
    # the thermal image at inverse depth w = k * _W_STEP (lo >= hi: none); view.reach[v, k]:
    # the first and last thermal rows they land in (first > last: none)
    a0, a1, a2, brow = rays
    lo, hi, reach = view
    h = brow.shape[0]
    w = a0.shape[1]
    w_t = np.int32(lens.width)
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
                i = _project(d, scale, a0[rv, u], a1[rv, u], a2[rv, u], b[0], b[1], b[2], lens)[5]
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


def sampling_lag(reach: NDArray[np.int32]) -> int:
    """Depth rows: how far apart two depth rows can be and still meet in the z-buffer, one
    landing in a thermal row that the other samples (its nearest pixel's row or, bilinear,
    the row above or below), at any depth the view table covers. reach (H, K, 2): the first
    and last thermal row of each depth row at each of the table's depths (:func:`view_table`).
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
def zbuffer(depth, scale, rays, lens, view, keys):  # pragma: no cover - JIT
    # keys (n_chunks, h_t * w_t): each chunk of rows fills its own; merged into keys[0]
    a0, a1, a2, brow = rays
    lo, hi = view.lo, view.hi
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
                _, _, px, py, pz, i = _project(dr[u], scale, c0[u], c1[u], c2[u], b0, b1, b2, lens)
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
def dilate_keys(keys, radius, tmp, out):  # pragma: no cover - JIT
    # out = the smallest key within `radius` pixels each way (a (2 r + 1)^2 box), as two 1-D
    # passes through tmp; keys, tmp, out (h_t, w_t) uint64. When the thermal camera's pixels
    # are finer than the depth camera's, neighbouring depth pixels land more than one
    # thermal pixel apart and the z-buffer has holes: through them a hidden surface would
    # take the temperature of what hides it. Each thermal pixel takes the nearest surface
    # around it, as far as the depth pixels' spacing (ReprojectMethod chooses the radius).
    h, w = keys.shape
    for v in numba.prange(h):
        for u in range(w):
            best = keys[v, u]
            for du in range(max(u - radius, 0), min(u + radius + 1, w)):
                best = min(best, keys[v, du])
            tmp[v, u] = best
    for v in numba.prange(h):
        for u in range(w):
            best = tmp[v, u]
            for dv in range(max(v - radius, 0), min(v + radius + 1, h)):
                best = min(best, tmp[dv, u])
            out[v, u] = best


@numba.njit(parallel=True, **_JIT)
def sample(
    depth, scale, rays, lens, view, values, nearest_z, build, how, into, sums
):  # pragma: no cover - JIT
    # values, nearest_z (h_t * w_t): each thermal pixel's value and the Z of its nearest
    # surface (FAR_M: none). build: nearest_z is yet to fill (all FAR_M). Each chunk of rows
    # then fills a copy of its own, in one pass: it projects its rows, and the rows around
    # them that can land in a thermal pixel its rows sample, in order, each once, into a ring
    # of lag + 1 rows (`how.lag`: the farthest apart two rows can meet, sampling_lag), and
    # samples a row as soon as no row still to project can land in the thermal rows it
    # samples (view.reach: the view table's thermal rows per depth row and grid point). One
    # parallel region and one projection per pixel, where building the whole z-buffer first
    # takes two of each. into.near[k] = 1: a row chunk k looked at has depth nearer than the
    # view table reaches; its pixels can land anywhere, so the caller must build the whole
    # z-buffer and call again. into.index (H, W) gets the flat thermal index each depth pixel
    # took (-1: none) if into.want_index (into.thermal_index). sums (RowSums): the regions'
    # sums of each row, once it is sampled (sum_row), while the row is in cache.
    a0, a1, a2, brow = rays
    lo, hi, reach = view
    out, reason, index, want_index, near = into
    bits = out.view(np.int32)
    tol_sigma, tol_slope = how.tol_sigma, how.tol_slope
    bilinear, n_chunks = how.bilinear, how.n_chunks
    h, w = depth.shape
    nan = np.float32(np.nan)
    lag = how.lag if build else 0
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
        scratch = np.empty((2, w), np.int32)
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
                # loops over views that start at 0 (see zbuffer)
                dr, c0, c1, c2 = depth[p, u0:u1], a0[rp, u0:u1], a1[rp, u0:u1], a2[rp, u0:u1]
                ur, vr, zr, ir = ut[uv], vt[uv], zt[slot], idx[slot]
                if bilinear:  # nearest needs no (u, v): not storing them is 3-4 % faster
                    for u in range(dr.size):
                        ur[u], vr[u], _, _, zr[u], ir[u] = _project(
                            dr[u], scale, c0[u], c1[u], c2[u], b0, b1, b2, lens
                        )
                else:
                    for u in range(dr.size):
                        _, _, _, _, zr[u], ir[u] = _project(
                            dr[u], scale, c0[u], c1[u], c2[u], b0, b1, b2, lens
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
                        lens,
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
                # outside the span no pixel has a value: the regions sum the span only
                sum_row(sums, v, u0, drow[u0:u1], orow, bits[v, u0:u1], rrow, ir[:n], scratch)
                v += 1


@numba.njit(inline="always", **_JIT)
def _fill_outside(drow, orow, rrow):  # pragma: no cover - JIT
    nan = np.float32(np.nan)
    for u in range(drow.size):
        orow[u] = nan
        rrow[u] = Reason.INVALID_DEPTH if drow[u] == 0 else Reason.OUTSIDE


@numba.njit(inline="always", **_JIT)
def _bilinear_row(
    ut, vt, zt, rrow, orow, values, zbuf, lens, tol_sigma, tol_slope
):  # pragma: no cover
    # bilinear over the neighbours that see the same surface as the depth pixel
    w_t, h_t = int(lens.width), int(lens.height)
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


# Region sums: integers only, so that the totals do not depend on how rows are split between
# threads or pixels between vector lanes, and a region summed while sampling equals the same
# region summed afterwards (scan_regions) or by numpy (thermodepth.measure.roi_stats).
FIXED_POINT = 2**12
"""Sampled values are summed as whole multiples of 2^-12 (rounded half up) of their unit."""
VALUE_LIMIT = 8191.0
"""Values are clipped to +-8191 before they are summed: q^2 over a row then fits int64."""
NO_MIN, NO_MAX = np.int32(2**31 - 1), np.int32(-(2**31))
_ABS, _INF_BITS, _SIGN = np.int32(0x7FFFFFFF), np.int32(0x7F800000), np.int32(31)


# Not inlined: numba (0.68) loses the writes into an array taken from a tuple inside a
# prange body, but not inside a function that the body calls (and one call per row is free).
@numba.njit(**_JIT)
def sum_row(rs, v, u0, drow, trow, bits, rrow, irow, scratch):  # pragma: no cover - JIT
    # The pixels u0 <= u < u0 + drow.size of depth row v: raw depth drow, sampled values trow
    # (bits: the same as int32), reasons rrow and the thermal pixels they see irow (flat
    # index; any where the reason is not OK), all sliced from u0; scratch: (2, >= that) int32.
    # Into rs.sums[r, :, v] and rs.keys[r, :, v] for every region r: the sums over its members
    # with a finite value, and the OR of rs.flags over the thermal pixels its members see
    # (Reason.OK), with a value or not: a flag says why not.
    # Every loop is int32 only (numba widens int32 arithmetic to int64 unless cast back, and
    # one int64 in a loop halves its vector width: measured 1.5x slower) but the last, which
    # sums q in int64. A first cheap loop finds the span of the region's members in the row;
    # the others run over that span only (a depth range's members are a fraction of its box:
    # measured, the whole-image depth range of bench_pipeline 0.14 -> 0.1 ms). Rows sliced
    # to start at 0 so the loops vectorise.
    limit = np.float32(VALUE_LIMIT)
    scale = np.float32(FIXED_POINT)
    half = np.float32(0.5)
    zero = np.int32(0)
    one = np.int32(1)
    n_px = drow.size
    flags = rs.flags
    for r in range(rs.boxes.shape[0]):
        v0, v1, c0, c1 = rs.boxes[r, 0], rs.boxes[r, 1], rs.boxes[r, 2], rs.boxes[r, 3]
        a = max(c0 - u0, 0)
        b = min(c1 - u0, n_px)
        n = zero
        s = np.int64(0)
        s2 = np.int64(0)
        fl = zero
        kmin, kmax = NO_MIN, NO_MAX
        if v0 <= v < v1 and a < b:
            lo, hi = np.int32(rs.units[r, 0]), np.int32(rs.units[r, 1])
            at = rs.mask_at[r, 0] + (v - v0) * rs.mask_at[r, 1] + (u0 + a - c0)
            d, m = drow[a:b], rs.masks[at : at + b - a]
            first, last = NO_MIN, NO_MAX
            k = zero  # u, as int32
            for u in range(b - a):
                du = np.int32(d[u])
                member = (du >= lo) & (du <= hi) & (np.int32(m[u]) != zero)
                first = min(first, k if member else NO_MIN)
                last = max(last, k if member else NO_MAX)
                k = np.int32(k + one)
            if first <= last:
                a, b = a + first, a + last + 1
                d, m = drow[a:b], rs.masks[at + first : at + last + 1]
                t, bt, rr, ix = trow[a:b], bits[a:b], rrow[a:b], irow[a:b]
                q, seen = scratch[0, : b - a], scratch[1, : b - a]
                for u in range(b - a):
                    i = bt[u]
                    du = np.int32(d[u])
                    member = (du >= lo) & (du <= hi) & (np.int32(m[u]) != zero)
                    ok = (np.int32(i & _ABS) < _INF_BITS) & member
                    x = np.int32(np.floor(min(max(t[u], -limit), limit) * scale + half))
                    q[u] = x if ok else zero
                    n = np.int32(n + np.int32(ok))
                    key = np.int32(i ^ np.int32(np.int32(i >> _SIGN) & _ABS))
                    kmin = min(kmin, key if ok else NO_MIN)
                    kmax = max(kmax, key if ok else NO_MAX)
                    seen[u] = np.int32(member & (np.int32(rr[u]) == zero))
                if flags.size > 0:
                    for u in range(b - a):
                        f = flags[max(ix[u], zero)]
                        fl = np.int32(fl | (f if seen[u] != zero else zero))
                for u in range(b - a):
                    x64 = np.int64(q[u])
                    s += x64
                    s2 += x64 * x64
        rs.sums[r, 0, v] = n
        rs.sums[r, 1, v] = s
        rs.sums[r, 2, v] = s2
        rs.sums[r, 3, v] = fl
        rs.keys[r, 0, v] = kmin
        rs.keys[r, 1, v] = kmax


@numba.njit(parallel=True, **_JIT)
def scan_regions(depth, values, reason, index, rs):  # pragma: no cover - JIT
    # sum_row over every row of an image already sampled: values (H, W) float32, reason
    # (H, W) uint8, index (H, W) int32 the thermal pixel of each depth pixel
    bits = values.view(np.int32)
    w = depth.shape[1]
    for v in numba.prange(depth.shape[0]):
        scratch = np.empty((2, w), np.int32)
        sum_row(rs, v, 0, depth[v], values[v], bits[v], reason[v], index[v], scratch)
