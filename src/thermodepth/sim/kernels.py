"""The simulator's numba kernels: ray casting (:mod:`.raycast`), what each ray meets (the
material, patterns included) and the radiance it brings (:mod:`.shading`), and whole renders
that cast, shade and average each pixel's sub-rays in one pass.

They live in one module because numba's cache (``cache=True``) is invalidated only by a change
to the file of the function compiled: a kernel that called a helper of another module would
keep running the helper's old code after an edit.

The shading helpers give, bit for bit, what the numpy expressions they stand for give
(:func:`~thermodepth.radiometry.fresnel_emissivity`,
:func:`~thermodepth.radiometry.atmospheric_transmission`, numpy's pairwise mean, einsum's
dot products): the same operations in the same order, no fused multiply-adds (numba does not
contract without ``fastmath``). tests/test_shading.py holds them to it.

The work is done a batch of rays at a time (a row of a grid, a chunk of a list): a helper
that takes arrays costs two atomic reference counts per array per call, which per ray would
cost more than the ray (helpers of scalars alone are free).

Layouts. A rect's kernel parameters, camera (or world) frame, one row of ``prims`` (R, 14):
n (3), n.c, u (3), u.c, v (3), v.c, half_u, half_v. A scene's surfaces (:class:`.shading.
SurfaceTable`): ``slots`` (R, 2), each rect's material and its pattern's second material (-1:
none) as rows of the material table; ``pattern`` (R, 4): kind (0 none, 1 checkerboard: square
size, columns and rows of squares; 2 circle grid: radius squared, first circle and how many in
``circles`` (C, 2), their centres (s, q)); ``missed``: the row of rays that meet nothing.
Thermal shading: ``mat`` (M, 5) per material row: L(T), emissivity, n^2 (Fresnel index
squared), directional (0/1), specular (0/1); ``geo`` (R, 13) per rect, world frame: distance
of its plane from the eye, centre (3), u (3), v (3), normal (3); ``env`` (8,): L(T_amb), the
air's two exponent coefficients and their weights, the eye (3).
"""

from __future__ import annotations

import numba
import numpy as np

# pattern kinds (column 0 of a scene's pattern table; 0: none)
CHECKERBOARD, CIRCLE_GRID = 1.0, 2.0

# columns of the thermal material table
L_OBJ, EMISSIVITY, INDEX_SQUARED, DIRECTIONAL, SPECULAR = range(5)

MAX_SUPERSAMPLE = 128  # the footprint's sum is numpy's pairwise one up to 128 terms a row


# -- ray casting -------------------------------------------------------------------------------

CHUNK = 4096  # rays per batch of a list of rays


@numba.njit(cache=True)
def _grid_row(xs, ys, r, prims, bbox, z, ids, s_out, q_out):  # pragma: no cover - JIT
    # the nearest rect along each ray of grid row r into row buffers (W,): each rect tested
    # only inside its bounding box (rows bbox[p, 0:2], columns bbox[p, 2:4])
    w = xs.shape[1]
    for c in range(w):
        z[c] = np.inf
        ids[c] = -1
        s_out[c] = np.nan
        q_out[c] = np.nan
    for p in range(prims.shape[0]):
        if r < bbox[p, 0] or r > bbox[p, 1]:
            continue
        n0, n1, n2, nc = prims[p, 0], prims[p, 1], prims[p, 2], prims[p, 3]
        u0, u1, u2, uc = prims[p, 4], prims[p, 5], prims[p, 6], prims[p, 7]
        v0, v1, v2, vc = prims[p, 8], prims[p, 9], prims[p, 10], prims[p, 11]
        hu, hv = prims[p, 12], prims[p, 13]
        for c in range(bbox[p, 2], bbox[p, 3] + 1):
            x = xs[r, c]
            y = ys[r, c]
            nd = n0 * x + n1 * y + n2
            if nd == 0.0:
                continue
            t = nc / nd
            if t <= 0.0 or t >= z[c]:
                continue
            s = t * (u0 * x + u1 * y + u2) - uc
            if abs(s) > hu:
                continue
            q = t * (v0 * x + v1 * y + v2) - vc
            if abs(q) > hv:
                continue
            z[c] = t
            ids[c] = p
            s_out[c] = s
            q_out[c] = q


@numba.njit(cache=True)
def _ray_range(z, x, y):  # pragma: no cover - JIT
    # the range of a hit at depth z along the ray (x, y, 1)
    return z * np.sqrt(x * x + y * y + 1.0)


@numba.njit(parallel=True, cache=True)
def cast_grid(xs, ys, prims, bbox, z_out, id_out, s_out, q_out, r_out):  # pragma: no cover
    """What each ray (x, y, 1) of a grid (H, W) meets: depth, rect, (s, q), range."""
    h, w = xs.shape
    for r in numba.prange(h):
        _grid_row(xs, ys, r, prims, bbox, z_out[r], id_out[r], s_out[r], q_out[r])
        for c in range(w):
            r_out[r, c] = _ray_range(z_out[r, c], xs[r, c], ys[r, c])


@numba.njit(parallel=True, cache=True)
def blocked(points, prims, tol, out):  # pragma: no cover - JIT
    """True where the segment from the origin to a point crosses a rect before the point."""
    for i in numba.prange(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        hit = False
        if z != z:  # NaN point
            out[i] = False
            continue
        for p in range(prims.shape[0]):
            nd = prims[p, 0] * x + prims[p, 1] * y + prims[p, 2] * z
            if nd == 0.0:
                continue
            t = prims[p, 3] / nd
            if t <= 1e-9 or t >= 1.0 - tol:
                continue
            s = t * (prims[p, 4] * x + prims[p, 5] * y + prims[p, 6] * z) - prims[p, 7]
            if abs(s) > prims[p, 12]:
                continue
            q = t * (prims[p, 8] * x + prims[p, 9] * y + prims[p, 10] * z) - prims[p, 11]
            if abs(q) > prims[p, 13]:
                continue
            hit = True
            break
        out[i] = hit


@numba.njit(cache=True)
def _nearest(origins, dirs, skip, prims, t_out, id_out, s_out, q_out):  # pragma: no cover
    # the nearest rect along each ray o + t d (t > 0) but its ``skip``, every rect tested
    for i in range(origins.shape[0]):
        ox, oy, oz = origins[i, 0], origins[i, 1], origins[i, 2]
        dx, dy, dz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
        best = np.inf
        best_p = -1
        best_s = np.nan
        best_q = np.nan
        for p in range(prims.shape[0]):
            if p == skip[i]:
                continue
            nd = prims[p, 0] * dx + prims[p, 1] * dy + prims[p, 2] * dz
            if nd == 0.0:
                continue
            t = (prims[p, 3] - (prims[p, 0] * ox + prims[p, 1] * oy + prims[p, 2] * oz)) / nd
            if t <= 1e-9 or t >= best:
                continue
            x, y, z = ox + t * dx, oy + t * dy, oz + t * dz
            s = prims[p, 4] * x + prims[p, 5] * y + prims[p, 6] * z - prims[p, 7]
            if abs(s) > prims[p, 12]:
                continue
            q = prims[p, 8] * x + prims[p, 9] * y + prims[p, 10] * z - prims[p, 11]
            if abs(q) > prims[p, 13]:
                continue
            best, best_p, best_s, best_q = t, p, s, q
        t_out[i] = best
        id_out[i] = best_p
        s_out[i] = best_s
        q_out[i] = best_q


@numba.njit(parallel=True, cache=True)
def cast_rays(origins, dirs, skip, prims, t_out, id_out, s_out, q_out):  # pragma: no cover
    """The nearest rect along each ray o + t d (t > 0), all rects tested: rays go anywhere."""
    n = origins.shape[0]
    for k in numba.prange((n + CHUNK - 1) // CHUNK):
        a, b = k * CHUNK, min(n, (k + 1) * CHUNK)
        _nearest(
            origins[a:b], dirs[a:b], skip[a:b], prims, t_out[a:b], id_out[a:b], s_out[a:b],
            q_out[a:b],
        )  # fmt: skip


# -- what a ray meets --------------------------------------------------------------------------


@numba.njit(cache=True, error_model="numpy")
def _slots(ids, s, q, slots, pattern, circles, missed, out):  # pragma: no cover - JIT
    # the material row of each hit: its rect's, or its pattern's second material's where the
    # pattern puts it (scene.Checkerboard / CircleGrid.second_material, per ray)
    for c in range(ids.shape[0]):
        rect = ids[c]
        if rect < 0:
            out[c] = missed
            continue
        kind = pattern[rect, 0]
        second = False
        if kind == CHECKERBOARD:
            size, n_u, n_v = pattern[rect, 1], pattern[rect, 2], pattern[rect, 3]
            i = np.floor(s[c] / size + n_u / 2.0)
            j = np.floor(q[c] / size + n_v / 2.0)
            second = i >= 0 and i < n_u and j >= 0 and j < n_v and (i + j) % 2 == 1
        elif kind == CIRCLE_GRID:
            r2, first = pattern[rect, 1], int(pattern[rect, 2])
            for k in range(first, first + int(pattern[rect, 3])):
                ds = s[c] - circles[k, 0]
                dq = q[c] - circles[k, 1]
                if ds * ds + dq * dq <= r2:
                    second = True
                    break
        out[c] = slots[rect, 1] if second else slots[rect, 0]


@numba.njit(parallel=True, cache=True)
def material_slots(ids, s, q, slots, pattern, circles, missed, out):  # pragma: no cover
    """The material row of each hit (N,)."""
    n = ids.shape[0]
    for k in numba.prange((n + CHUNK - 1) // CHUNK):
        a, b = k * CHUNK, min(n, (k + 1) * CHUNK)
        _slots(ids[a:b], s[a:b], q[a:b], slots, pattern, circles, missed, out[a:b])


@numba.njit(cache=True, error_model="numpy")
def _fresnel(cos, n2):  # pragma: no cover - JIT
    # radiometry.fresnel_emissivity of one ray, n2 the index squared
    c = min(max(abs(cos), 1e-12), 1.0)
    g = np.sqrt(n2 - 1.0 + c * c)
    rs = (c - g) / (c + g)
    rp = (n2 * c - g) / (n2 * c + g)
    return 1.0 - 0.5 * (rs * rs + rp * rp)


@numba.njit(cache=True)
def _air(distance, k1, k2, w1, w2):  # pragma: no cover - JIT
    # radiometry.atmospheric_transmission of one path: w1 exp(k1 sqrt d) + w2 exp(k2 sqrt d)
    sd = np.sqrt(distance)
    return w1 * np.exp(sd * k1) + w2 * np.exp(sd * k2)


@numba.njit(cache=True)
def _leaving(tau, emis, l_obj, l_refl, l_amb):  # pragma: no cover - JIT
    # what reaches the end of an air path tau long from a surface that emits eps L(T) and
    # reflects (1 - eps) L_r, the air adding its own (1 - tau) L(T_amb)
    return tau * (emis * l_obj + (1.0 - emis) * l_refl) + (1.0 - tau) * l_amb


@numba.njit(cache=True)
def _dot(ax, ay, az, bx, by, bz):  # pragma: no cover - JIT
    # numpy's einsum("ij,ij->i") of three terms sums them as (0 + 2) + 1 (its SIMD lanes)
    return (ax * bx + az * bz) + ay * by


@numba.njit(cache=True, error_model="numpy")
def _mirrored(
    ids, s, q, rows, slots, pattern, circles, missed, mat, geo, world, env, out
):  # pragma: no cover - JIT
    # for each ray from the eye (env[5:8]) that meets a specular rect at (s, q): the radiance
    # its mirrored ray brings back, what it meets at its temperature and (directional)
    # emissivity reflecting the ambient, through the air between (the ambient if nothing)
    todo = np.flatnonzero(_specular(rows, mat))
    if todo.size == 0:
        return
    k = todo.size
    o, d = np.empty((k, 3)), np.empty((k, 3))
    skip = np.empty(k, np.int64)
    for i in range(k):
        c = todo[i]
        rect = ids[c]
        px = (geo[rect, 1] + s[c] * geo[rect, 4]) + q[c] * geo[rect, 7]
        py = (geo[rect, 2] + s[c] * geo[rect, 5]) + q[c] * geo[rect, 8]
        pz = (geo[rect, 3] + s[c] * geo[rect, 6]) + q[c] * geo[rect, 9]
        vx, vy, vz = px - env[5], py - env[6], pz - env[7]
        norm = np.sqrt((vx * vx + vy * vy) + vz * vz)
        vx, vy, vz = vx / norm, vy / norm, vz / norm
        nx, ny, nz = geo[rect, 10], geo[rect, 11], geo[rect, 12]
        twice = 2.0 * _dot(vx, vy, vz, nx, ny, nz)
        o[i, 0], o[i, 1], o[i, 2] = px, py, pz
        d[i, 0], d[i, 1], d[i, 2] = vx - twice * nx, vy - twice * ny, vz - twice * nz
        skip[i] = rect  # it never meets the mirror again
    t, hit, s2, q2 = np.empty(k), np.empty(k, np.int64), np.empty(k), np.empty(k)
    _nearest(o, d, skip, world, t, hit, s2, q2)
    rows2 = np.empty(k, np.int64)
    _slots(hit, s2, q2, slots, pattern, circles, missed, rows2)
    l_amb = env[0]
    for i in range(k):
        m, h = rows2[i], hit[i]
        emis = mat[m, EMISSIVITY]
        if mat[m, DIRECTIONAL] > 0:
            cos = _dot(d[i, 0], d[i, 1], d[i, 2], geo[h, 10], geo[h, 11], geo[h, 12])
            emis = _fresnel(cos, mat[m, INDEX_SQUARED])
        tau = _air(t[i] if h >= 0 else 0.0, env[1], env[2], env[3], env[4])
        out[todo[i]] = _leaving(tau, emis, mat[m, L_OBJ], l_amb, l_amb)


@numba.njit(cache=True)
def _specular(rows, mat):  # pragma: no cover - JIT
    # which rays meet a specular material
    out = np.zeros(rows.shape[0], np.bool_)
    for c in range(rows.shape[0]):
        out[c] = mat[rows[c], SPECULAR] > 0
    return out


@numba.njit(cache=True, error_model="numpy")
def _radiance(
    ids, s, q, dist, rows, slots, pattern, circles, missed, mat, geo, world, env, bounce, out
):  # pragma: no cover - JIT
    # the in-band radiance at the aperture along rays from the eye that meet ``ids`` at
    # (s, q) after ``dist`` of air, of material ``rows`` (shading.aperture_radiance);
    # ``bounce``: mirrors reflect what their mirrored rays meet, else the ambient
    l_amb, k1, k2, w1, w2 = env[0], env[1], env[2], env[3], env[4]
    for c in range(ids.shape[0]):
        out[c] = l_amb  # the reflected radiance, until the emission is added
    if bounce:
        _mirrored(ids, s, q, rows, slots, pattern, circles, missed, mat, geo, world, env, out)
    for c in range(ids.shape[0]):
        m, rect = rows[c], ids[c]
        emis = mat[m, EMISSIVITY]
        if mat[m, DIRECTIONAL] > 0:  # a ray from the eye meets a plane D away at D / range
            emis = _fresnel(geo[rect, 0] / dist[c], mat[m, INDEX_SQUARED])
        tau = _air(dist[c] if rect >= 0 else 0.0, k1, k2, w1, w2)
        out[c] = _leaving(tau, emis, mat[m, L_OBJ], out[c], l_amb)


@numba.njit(parallel=True, cache=True)
def radiance_rays(
    ids, s, q, dist, slots, pattern, circles, missed, mat, geo, world, env, bounce, out
):  # pragma: no cover - JIT
    """The aperture radiance along each of N rays from the eye (N,)."""
    n = ids.shape[0]
    for k in numba.prange((n + CHUNK - 1) // CHUNK):
        a, b = k * CHUNK, min(n, (k + 1) * CHUNK)
        rows = np.empty(b - a, np.int64)
        _slots(ids[a:b], s[a:b], q[a:b], slots, pattern, circles, missed, rows)
        _radiance(
            ids[a:b], s[a:b], q[a:b], dist[a:b], rows, slots, pattern, circles, missed, mat,
            geo, world, env, bounce, out[a:b],
        )  # fmt: skip


# -- pixel footprints and whole renders --------------------------------------------------------


@numba.njit(cache=True)
def _add_footprints(row, ss, acc):  # pragma: no cover - JIT
    # one sub-row's share of each pixel's sum, as numpy's mean over axes (1, 3) of
    # (h, ss, w, ss) adds it: the sub-row's ss values by numpy's pairwise sum (up to 128:
    # eight partial sums past 8 values), then onto the pixel's sum
    for j in range(acc.shape[0]):
        a = j * ss
        if ss < 8:
            total = 0.0
            for i in range(a, a + ss):
                total += row[i]
        else:
            r0, r1, r2, r3 = row[a], row[a + 1], row[a + 2], row[a + 3]
            r4, r5, r6, r7 = row[a + 4], row[a + 5], row[a + 6], row[a + 7]
            i = a + 8
            end8 = a + ss - ss % 8
            while i < end8:
                r0 += row[i]
                r1 += row[i + 1]
                r2 += row[i + 2]
                r3 += row[i + 3]
                r4 += row[i + 4]
                r5 += row[i + 5]
                r6 += row[i + 6]
                r7 += row[i + 7]
                i += 8
            total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
            while i < a + ss:
                total += row[i]
                i += 1
        acc[j] += total


@numba.njit(cache=True)
def _footprint_means(acc, ss, out_row):  # pragma: no cover - JIT
    # each pixel's sum of its ss x ss sub-rays -> their mean
    for j in range(out_row.shape[0]):
        out_row[j] = acc[j] / (ss * ss)


@numba.njit(cache=True)
def _hit_buffers(n):  # pragma: no cover - JIT
    # a row of n rays' hits: depth z, rect ids, the rect coordinates s, q, material rows
    return np.empty(n), np.empty(n, np.int64), np.empty(n), np.empty(n), np.empty(n, np.int64)


@numba.njit(cache=True)
def _cast_row(
    xs, ys, r, prims, bbox, slots, pattern, circles, missed, z, ids, s, q, rows
):  # pragma: no cover - JIT
    # grid row r's rays cast (_grid_row) and the material row of each hit (_slots)
    _grid_row(xs, ys, r, prims, bbox, z, ids, s, q)
    _slots(ids, s, q, slots, pattern, circles, missed, rows)


@numba.njit(parallel=True, cache=True)
def footprint(sub, ss, out):  # pragma: no cover - JIT
    """The mean of each pixel's ss x ss sub-rays (h ss, w ss) -> (h, w), bit for bit numpy's
    ``sub.reshape(h, ss, w, ss).mean(axis=(1, 3))``."""
    h, w = out.shape
    for i in numba.prange(h):
        acc = np.zeros(w)
        for a in range(ss):
            _add_footprints(sub[i * ss + a], ss, acc)
        _footprint_means(acc, ss, out[i])


@numba.njit(parallel=True, cache=True)
def render_albedo(
    xs, ys, ss, prims, bbox, slots, pattern, circles, missed, albedo, out
):  # pragma: no cover - JIT
    """The mean near-IR albedo of each pixel's sub-rays (h, w): cast, looked up and averaged
    a row of pixels at a time (the sub-ray grid xs, ys is (h ss, w ss))."""
    h, w = out.shape
    n = w * ss
    for i in numba.prange(h):
        z, ids, s, q, rows = _hit_buffers(n)
        value, acc = np.empty(n), np.zeros(w)
        for a in range(ss):
            _cast_row(xs, ys, i * ss + a, prims, bbox, slots, pattern, circles, missed,
                      z, ids, s, q, rows)  # fmt: skip
            for c in range(n):
                value[c] = albedo[rows[c]]
            _add_footprints(value, ss, acc)
        _footprint_means(acc, ss, out[i])


@numba.njit(parallel=True, cache=True)
def render_radiance(
    xs, ys, ss, prims, bbox, slots, pattern, circles, missed, mat, geo, world, env, bounce, out
):  # pragma: no cover - JIT
    """The mean aperture radiance of each pixel's sub-rays (h, w): cast, shaded and averaged
    a row of pixels at a time (the sub-ray grid xs, ys is (h ss, w ss))."""
    h, w = out.shape
    n = w * ss
    for i in numba.prange(h):
        z, ids, s, q, rows = _hit_buffers(n)
        dist, value, acc = np.empty(n), np.empty(n), np.zeros(w)
        for a in range(ss):
            r = i * ss + a
            _cast_row(xs, ys, r, prims, bbox, slots, pattern, circles, missed, z, ids, s, q, rows)
            for c in range(n):
                dist[c] = _ray_range(z[c], xs[r, c], ys[r, c])
            _radiance(
                ids, s, q, dist, rows, slots, pattern, circles, missed, mat, geo, world, env,
                bounce, value,
            )  # fmt: skip
            _add_footprints(value, ss, acc)
        _footprint_means(acc, ss, out[i])
