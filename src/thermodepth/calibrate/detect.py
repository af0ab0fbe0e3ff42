"""Finding a calibration board in one image: OpenCV's detectors on a stretched, upscaled image
in both polarities, corners refined on fronto-parallel patches, the larger-board check, and a
corner order the two cameras of a pair agree on."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import map_coordinates

from ..board import BoardSpec
from .images import plain_grey, stretch_to_unit, upscale_factor

FloatArray = NDArray[np.float64]

_TERM = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
"""cornerSubPix stop rule of OpenCV's calibration sample: 30 iterations or a step < 0.01 px."""


@dataclass(frozen=True)
class Detection:
    """Board points found in one image: ``points_px`` (N, 2) in the image's pixels (OpenCV
    conventions), in the order of :meth:`BoardSpec.object_points_m`; ``inverted`` if found
    in the negative; ``upscale`` the factor used; ``method`` the detector."""

    points_px: FloatArray
    inverted: bool
    upscale: int
    method: str


def detect_board(
    image: NDArray[Any],
    board: BoardSpec,
    stretch: bool | None = None,
    upscale: int | None = None,
    refine: str = "cornersubpix",
    quick: bool = False,
) -> Detection | None:
    """Find ``board`` in one image; None when it is not found.

    image: (H, W) any dtype. stretch: percentile stretch (:func:`stretch_to_unit`) before
    detection; by default for every image but uint8 ones, which are used as they are.
    upscale: integer factor (default :func:`upscale_factor`); cubic interpolation, then
    points map back as u = (u_up + 0.5) / s - 0.5 (pixel centres at integers). refine:
    ``cornersubpix`` or ``homography`` (:data:`REFINE_METHODS`).

    Checkerboards: ``cv2.findChessboardCorners`` (adaptive threshold; histogram
    equalisation only for unstretched images) on the 8-bit image and its negative, then
    ``cv2.findChessboardCornersSB`` at native scale, and last OpenCV's own call on the image
    as a user hands it (8-bit grey: :func:`~.images.plain_grey`): a board plain OpenCV finds
    is never missed. ``quick`` (for streams): no histogram equalisation, no exhaustive
    search, no last call (a 1280x720 image without the board: ~0.5 s instead of ~8 s).
    Corners are refined with
    ``cv2.cornerSubPix`` on the unclipped float image (its solution does not change under an
    affine map of intensity) with a half window of 0.6 x the smallest corner spacing, at most
    11 px at native scale (OpenCV's sample), stopping after 30 iterations or a 0.01 px step;
    then, with ``homography``, by :func:`refine_corners_homography`. The order is made
    canonical (:func:`canonical_order`). Circle grids: ``cv2.findCirclesGrid`` (asymmetric)
    with a blob detector sized to the image, on the image and its negative; blob centres are
    not refined further.
    """
    if stretch is None:
        stretch = image.dtype != np.uint8
    unit = stretch_to_unit(image) if stretch else image.astype(np.float32)
    if unit is None:
        return None
    native: NDArray[np.float32] = unit
    s = upscale_factor(image.shape) if upscale is None else int(upscale)
    fine = native
    if s > 1:
        fine = np.asarray(
            cv2.resize(native, None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC), np.float32
        )
    img8 = np.clip(np.rint(fine), 0, 255).astype(np.uint8)
    found = (
        _find_checkerboard(img8, fine, board, s, stretch, plain_grey(image), quick)
        if board.kind == "checkerboard"
        else _find_circles(img8, board)
    )
    if found is None:
        return None
    pts, inverted, method = found
    pts = (pts + 0.5) / s - 0.5
    if board.kind == "checkerboard":
        if refine == "homography":
            pts = refine_corners_homography(native, pts, board)
        pts = canonical_order(pts, board)
    return Detection(pts, inverted, s, method)


def _min_spacing(points: FloatArray, board: BoardSpec) -> float:
    g = points.reshape(board.rows, board.cols, 2)
    along = np.linalg.norm(np.diff(g, axis=1), axis=2).min()
    across = np.linalg.norm(np.diff(g, axis=0), axis=2).min()
    return float(min(along, across))


def _find_checkerboard(
    img8: NDArray[np.uint8],
    fine: NDArray[np.float32],
    board: BoardSpec,
    s: int,
    stretched: bool,
    plain8: NDArray[np.uint8],
    quick: bool,
) -> tuple[FloatArray, bool, str] | None:
    size = board.pattern_size
    adaptive, normalise = cv2.CALIB_CB_ADAPTIVE_THRESH, cv2.CALIB_CB_NORMALIZE_IMAGE
    fast = cv2.CALIB_CB_FAST_CHECK  # rejects images without a board quickly; same corners
    default = adaptive | normalise  # OpenCV's own flags
    # the image as a user hands it to OpenCV: then OpenCV's own call (default flags, no fast
    # check) is one of ours, and a board it finds is never missed
    as_is = not stretched and s == 1
    # A stretched image is normalised already: equalising its histogram again blows up the
    # noise of a uniform background (a thermal scene is mostly wall) and breaks the quads
    # (measured on simulated Lepton views: 20 of 20 found without it, 16 with it). Quick:
    # no equalising (on a 1280x720 image without the board it takes ~3.5 s, measured).
    tries = [adaptive] if quick else [adaptive, default]
    if not stretched and not quick:  # OpenCV's default flags first, as its samples use
        tries.reverse()
    for flags in tries:
        check = 0 if (as_is and flags == default) else fast
        for inverted in (False, True):
            ok, c = cv2.findChessboardCorners(
                255 - img8 if inverted else img8, size, flags=flags | check
            )
            if ok:
                return _refine(c, fine, board, s), inverted, "findChessboardCorners"
    # the sector-based detector copes with blur at native scale
    native = (
        img8 if s == 1 else cv2.resize(img8, None, fx=1 / s, fy=1 / s, interpolation=cv2.INTER_AREA)
    )
    sb = 0 if quick else normalise | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    for inverted in (False, True):
        ok, c = cv2.findChessboardCornersSB(255 - native if inverted else native, size, flags=sb)
        if ok:
            up = (c.reshape(-1, 2).astype(np.float64) + 0.5) * s - 0.5
            return _refine(up, fine, board, s), inverted, "findChessboardCornersSB"
    if quick or as_is:
        return None
    # last, OpenCV as a user would call it on the image before our stretch and upscale
    # (default flags, both detectors): a board it finds on its own is never missed
    for inverted in (False, True):
        for find in (cv2.findChessboardCorners, cv2.findChessboardCornersSB):
            ok, c = find(255 - plain8 if inverted else plain8, size)
            if ok:
                up = (c.reshape(-1, 2).astype(np.float64) + 0.5) * s - 0.5
                return _refine(up, fine, board, s), inverted, f"{find.__name__} (plain)"
    return None


def _refine(
    corners: NDArray[Any], fine: NDArray[np.float32], board: BoardSpec, s: int
) -> FloatArray:
    """cornerSubPix with a half window of 0.6 x the smallest corner spacing of the board
    (2 px at least, 11 px at native scale at most)."""
    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    half = int(min(11 * s, max(2, math.floor(0.6 * _min_spacing(pts, board)))))
    refined = cv2.cornerSubPix(
        fine, pts.astype(np.float32).reshape(-1, 1, 2), (half, half), (-1, -1), _TERM
    )
    out: FloatArray = refined.reshape(-1, 2).astype(np.float64)
    return out


REFINE_METHODS = ("homography", "cornersubpix")
"""Corner refinement: ``cornersubpix`` in the image (OpenCV's sample), or ``homography``:
then again on fronto-parallel patches (:func:`refine_corners_homography`)."""

HOMOGRAPHY_PATCH_PX_PER_SQUARE = 16
HOMOGRAPHY_WINDOW_SQUARES = 0.7
HOMOGRAPHY_EDGE_WINDOW_SQUARES = 0.35
HOMOGRAPHY_EDGE_AGREEMENT_SQUARES = 0.1
HOMOGRAPHY_REACH = 2


def refine_corners_homography(
    image: NDArray[np.float32], points_px: FloatArray, board: BoardSpec, iterations: int = 2
) -> FloatArray:
    """Checkerboard corners refined on fronto-parallel patches; (N, 2) px in and out.

    image: (H, W) float image at native scale (stretched, not clipped); points_px: the
    corners in :meth:`BoardSpec.object_points_m` order.

    On a small, blurred and tilted board, ``cornerSubPix`` in the image is biased: its window
    sees squares of different sizes on either side of a corner. Here each corner's
    neighbourhood is resampled so that the board looks square-on: a homography from the grid
    to the image is fitted to the corners within 2 squares of it (5 x 5 at most), the image is
    resampled on a patch of 16 px per square around the corner (cubic), ``cornerSubPix`` runs
    there with a half window of 0.7 squares (the X-junction is now symmetric, so a wide window
    averages the sampling errors of an undersampled sensor without bias), and the result maps
    back through the homography. On the grid's outer ring the outer squares may be cut by the
    board's edge (as in OpenCV's own sample images): there a 0.35-square window is tried too,
    and wins when the two disagree by more than 0.1 square. Two passes; the second uses the
    refined corners. Simulated Lepton views (123 views, tilts 15-45 deg): 0.089 px RMS from
    the true corners with ``cornerSubPix`` alone (worst view 0.57 px), 0.055 px after this
    (worst view 0.099 px); docs/calibration.md.
    """
    C = board.cols
    grid = np.stack(np.meshgrid(np.arange(C), np.arange(board.rows)), axis=-1).reshape(-1, 2)
    grid = grid.astype(np.float64)
    S = HOMOGRAPHY_PATCH_PX_PER_SQUARE
    w_inner = int(HOMOGRAPHY_WINDOW_SQUARES * S)
    w_edge = int(HOMOGRAPHY_EDGE_WINDOW_SQUARES * S)
    edge = (
        (grid[:, 0] == 0)
        | (grid[:, 0] == C - 1)
        | (grid[:, 1] == 0)
        | (grid[:, 1] == board.rows - 1)
    )
    n = w_inner + S // 4  # patch half size: the window plus a margin for the gradients
    ax = np.arange(-n, n + 1, dtype=np.float64) / S
    ga, gb = np.meshgrid(ax, ax)
    patch_grid = np.stack([ga.ravel(), gb.ravel(), np.ones(ga.size)])
    centre = np.array([[[n, n]]], dtype=np.float32)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 0.001)
    pts = np.asarray(points_px, dtype=np.float64).copy()
    for _ in range(iterations):
        new = pts.copy()
        for k in range(len(pts)):
            near = np.max(np.abs(grid - grid[k]), axis=1) <= HOMOGRAPHY_REACH
            h, _ = cv2.findHomography(grid[near] - grid[k], pts[near], 0)
            if h is None:
                continue
            m = h @ patch_grid
            map_u = (m[0] / m[2]).reshape(ga.shape).astype(np.float32)
            map_v = (m[1] / m[2]).reshape(ga.shape).astype(np.float32)
            patch = cv2.remap(image, map_u, map_v, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
            c = cv2.cornerSubPix(patch, centre.copy(), (w_inner, w_inner), (-1, -1), crit)
            if edge[k]:
                c_edge = cv2.cornerSubPix(patch, centre.copy(), (w_edge, w_edge), (-1, -1), crit)
                if np.linalg.norm(c - c_edge) > HOMOGRAPHY_EDGE_AGREEMENT_SQUARES * S:
                    c = c_edge
            c = c.reshape(2)
            a, b = (c.astype(np.float64) - n) / S
            q = h @ np.array([a, b, 1.0])
            new[k] = q[:2] / q[2]
        pts = new
    return pts


# Past each edge of a checkerboard's grid of inner corners lies a row of its outer squares,
# alternating with the board's own contrast; one step further lies the margin, which is
# uniform, however it is made (bare metal, a hot plate, a mask), or, on a board with more
# corners than the detector was told, more squares, alternating again. OpenCV finds such
# sub-grids, and not always the same one in the two cameras of a pair, so the pair would
# match different corners.
CONTINUES_FRACTION = 0.5
"""Alternation of the cells beyond an edge, as a fraction of the board's own (its outer
squares', in the phase a continuing pattern has), above which the pattern is taken to go
on: 1 where it goes on, 0 for a uniform margin (measured: docs/calibration.md)."""


def _cells(
    grid: FloatArray, outward: FloatArray, offset: float, spread: float = 0.25
) -> tuple[FloatArray, ...]:
    """Sample points of the cells along one edge of a grid of corners: the corners along the
    edge ``grid`` (n, 2), extended by one step at each end (the corner cells), and the cells
    between consecutive ones, ``offset`` grid steps outward (``outward``: (n, 2), one step
    out at each corner). Returns per cell a 3 x 3 grid of points (n + 1, 9, 2) and how far
    the samples reach (n + 1,), pixels."""
    ext = np.concatenate([2 * grid[:1] - grid[1:2], grid, 2 * grid[-1:] - grid[-2:-1]])
    out = np.concatenate([outward[:1], outward, outward[-1:]])
    centre = (ext[:-1] + ext[1:]) / 2 + offset * (out[:-1] + out[1:]) / 2
    along, across = ext[1:] - ext[:-1], (out[:-1] + out[1:]) / 2
    fa, fb = (x.ravel() for x in np.meshgrid([-0.25, 0.0, 0.25], [-spread, 0.0, spread]))
    points = centre[:, None] + fa[:, None] * along[:, None] + fb[:, None] * across[:, None]
    reach = (0.25 * np.abs(along) + spread * np.abs(across)).max(axis=1)
    return points, reach


def _alternation(values: FloatArray, usable: NDArray[np.bool_]) -> float:
    """How much a sequence of cells alternates: the mean of (c_k - c_k+1) (-1)^k over the
    consecutive pairs both usable (NaN when there are none)."""
    diff = (values[:-1] - values[1:]) * np.where(np.arange(values.size - 1) % 2 == 0, 1.0, -1.0)
    pair = usable[:-1] & usable[1:]
    return float(diff[pair].mean()) if pair.any() else float("nan")


def grid_continues(image: NDArray[Any], points_px: FloatArray, board: BoardSpec) -> tuple[str, ...]:
    """The edges (``"left"``, ``"right"``, ``"top"``, ``"bottom"`` of the grid as detected)
    past which a checkerboard's pattern goes on: the board has more corners than ``board``
    says.

    image: (H, W), any dtype (the score does not change under a monotonic map of intensity
    that keeps a uniform margin uniform: a palette's levels, a stretch); points_px: (rows *
    cols, 2) detected corners in grid order. Along each edge, two rows of cells are sampled
    (3 x 3 points each, a quarter step apart): the board's outer squares (half a step past
    the last corners) and what lies beyond them (one and a half steps). The outer squares
    alternate with the board's contrast; beyond them a margin is uniform, while a pattern
    that goes on alternates again, each cell the opposite of the square before it. An edge
    whose cells beyond alternate, in that phase, by more than
    :data:`CONTINUES_FRACTION` of the outer squares' alternation is one the pattern goes on
    past. Cells beyond the image are left out; an edge without two neighbouring cells inside
    is not judged.
    """
    img = np.asarray(image, dtype=np.float32)
    h, w = img.shape
    g = np.asarray(points_px, dtype=np.float64).reshape(board.rows, board.cols, 2)
    edges = {
        "left": (g[:, 0], g[:, 0] - g[:, 1]),
        "right": (g[:, -1], g[:, -1] - g[:, -2]),
        "top": (g[0, :], g[0, :] - g[1, :]),
        "bottom": (g[-1, :], g[-1, :] - g[-2, :]),
    }
    found = []
    for name, (corners, outward) in edges.items():
        means, usable = [], []
        for offset, spread in ((0.5, 0.25), (1.25, 0.12)):  # outer squares, then beyond
            points, reach = _cells(corners, outward, offset, spread)
            u, v = points[..., 0], points[..., 1]
            m = reach[:, None] + 1
            usable.append(np.all((u >= m) & (u <= w - 1 - m) & (v >= m) & (v <= h - 1 - m), axis=1))
            means.append(map_coordinates(img, [v, u], order=1).mean(axis=1))
        own = _alternation(means[0], usable[0] & usable[1])
        beyond = -_alternation(means[1], usable[0] & usable[1])  # a continuing pattern's phase
        if np.isfinite(own) and own != 0 and beyond / own > CONTINUES_FRACTION:
            found.append(name)
    return tuple(found)


def _find_circles(img8: NDArray[np.uint8], board: BoardSpec) -> tuple[FloatArray, bool, str] | None:
    params = cv2.SimpleBlobDetector.Params()
    area = float(img8.size)
    params.minArea = 10.0
    params.maxArea = area / max(board.cols * board.rows, 1)
    params.filterByConvexity = False
    params.filterByInertia = True
    params.minInertiaRatio = 0.2
    detector = cv2.SimpleBlobDetector.create(params)
    for inverted in (False, True):
        ok, c = cv2.findCirclesGrid(
            255 - img8 if inverted else img8,
            board.pattern_size,
            flags=cv2.CALIB_CB_ASYMMETRIC_GRID,
            blobDetector=detector,
        )
        if ok:
            return c.reshape(-1, 2).astype(np.float64), inverted, "findCirclesGrid"
    return None


# -- corner order -----------------------------------------------------------------------------


def _grid_directions(points: FloatArray, board: BoardSpec) -> tuple[FloatArray, FloatArray]:
    g = points.reshape(board.rows, board.cols, 2)
    along = np.mean(np.diff(g, axis=1), axis=(0, 1))  # +x of the board (along a row)
    down = np.mean(np.diff(g, axis=0), axis=(0, 1))  # +y of the board (next row)
    return along, down


def _symmetric_orders(points: FloatArray, board: BoardSpec) -> list[FloatArray]:
    """The re-orderings of a checkerboard's corners that map its point grid onto itself:
    the identity and the half turn; a square board also has the quarter turns."""
    g = points.reshape(board.rows, board.cols, 2)
    out = [g, g[::-1, ::-1]]
    if board.rows == board.cols:
        out += [np.rot90(g, 1, axes=(0, 1)), np.rot90(g, 3, axes=(0, 1))]
    return [o.reshape(-1, 2).copy() for o in out]


def canonical_order(points: FloatArray, board: BoardSpec) -> FloatArray:
    """Corners (N, 2) re-ordered so the board's +x runs rightwards in the image.

    A checkerboard has no marked origin: detectors may start at either end (and, on a square
    board, at any corner). First the handedness is fixed (the board seen from the front has
    +x then +y turning clockwise on screen, image v pointing down); then, among the orders
    that map the grid onto itself, the one whose +x direction is nearest the image's +u.
    A pair whose board stands near 90 degrees is made consistent by :func:`match_order`.
    """
    along, down = _grid_directions(points, board)
    if along[0] * down[1] - along[1] * down[0] < 0:  # mirrored: reverse each row
        points = points.reshape(board.rows, board.cols, 2)[:, ::-1].reshape(-1, 2).copy()
    return max(
        _symmetric_orders(points, board), key=lambda o: _unit(_grid_directions(o, board)[0])[0]
    )


def match_order(reference: FloatArray, points: FloatArray, board: BoardSpec) -> FloatArray:
    """``points`` re-ordered so that the board's +x points the way it does in ``reference``
    (the other camera of the pair, nearly parallel): the stereo fit needs corner k of both
    images to be the same physical corner. Checkerboards only; circle grids are returned
    as they are (an asymmetric grid fixes its own order)."""
    if board.kind != "checkerboard":
        return points
    ref = _unit(_grid_directions(reference, board)[0])
    return max(
        _symmetric_orders(points, board),
        key=lambda o: float(_unit(_grid_directions(o, board)[0]) @ ref),
    )


def _unit(v: FloatArray) -> FloatArray:
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else v
