"""Target-based calibration of the depth + thermal pair: thermal (and depth) intrinsics and
``thermal_from_depth`` from image pairs of a calibration board, with a quality report.

The method is OpenCV's two-step stereo calibration (Zhang's method per camera, then the
rigid transform with the intrinsics held fixed), which is stabler than a joint fit when one
camera has 19,200 pixels and the other 921,600:

1. :func:`discover_pairs` matches the images of a folder by name (rules in its docstring).
2. :func:`load_image` reads 8- or 16-bit PNG/TIFF/JPEG or ``.npy``; :func:`detect_board`
   stretches low-contrast (thermal, 14-bit) images by percentiles, upscales small ones, tries
   both polarities (a heated board's paint is bright where the print is dark), and refines
   corners to sub-pixel accuracy with ``cv2.cornerSubPix``; :func:`canonical_order` and
   :func:`match_order` make the corner order of the two images of a pair agree.
3. :func:`calibrate_camera` (``cv2.calibrateCamera``) per camera, or :func:`fixed_camera_fit`
   when the depth intrinsics are given; :func:`stereo_calibrate` (``cv2.stereoCalibrate``
   with ``CALIB_FIX_INTRINSIC``) for ``thermal_from_depth``.
4. :func:`run_calibration` ties them together, flags outlier images
   (:func:`flag_outliers`), optionally drops them and fits again, and builds the report
   (:class:`CalibrationResult`: :meth:`~CalibrationResult.report_dict`,
   :func:`plot_report`).

Units: lengths in metres (square size, translation), pixels for image coordinates (OpenCV
conventions: pixel centres at integers), angles in degrees in the report.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import NDArray
from pydantic import ValidationError
from scipy.ndimage import map_coordinates

from .calibration import (
    BoardSpec,
    Calibration,
    CameraSchema,
    DepthCameraSchema,
    describe_validation_error,
    intrinsics_of,
    read_mapping,
    write_mapping,
)
from .camera import Intrinsics, RigidTransform
from .errors import InputError

FloatArray = NDArray[np.float64]
Progress = Callable[[int], None]
"""Called with the number of units of work just done (for progress bars)."""

MIN_PAIRS = 6
"""Fewest usable pairs to calibrate with: each view of a planar board gives 2 constraints on
the intrinsics, and a fit of 4 + distortion parameters needs several well-spread views;
OpenCV's documentation recommends 10-20."""

IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".npy", ".jpg", ".jpeg", ".bmp", ".pgm")
DEPTH_ROLES = ("ir", "color", "rgb")
"""Name suffixes of the depth camera's image: ``_ir`` (infrared, shares the depth stream's
intrinsics and frame on a D435) or ``_color`` / ``_rgb`` (a colour camera)."""

# -- distortion models ------------------------------------------------------------------------

DISTORTION_MODELS: dict[str, int] = {
    # k1, k2, p1, p2, k3: OpenCV's default
    "full": 0,
    # k1, k2, p1, p2: the thermal camera's default. A 160x120 view rarely has board corners
    # past r = 0.5 (normalised), where k3 r^6 is a few % of k1 r^2: k3 is then fitted to noise
    # and bends the image corners (simulated rig, 25 poses, 10 seeds: registration off by up
    # to 0.50 px with k3, 0.22 px without). Tangential terms of a few 1e-4 are small in
    # pixels, but leaving them out moves the principal point by ~0.2 px even with perfect
    # corners, a ~0.09 deg rotation error (docs/calibration.md).
    "no-k3": cv2.CALIB_FIX_K3,
    # k1, k2: the depth camera's default. Its board views sit inside the thermal camera's
    # narrower field, the middle of its image, where higher terms cannot be told apart (a D435
    # IR stream is rectified: its true distortion is zero).
    "radial": cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
    # pinhole
    "none": cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST,
}
"""Which distortion coefficients ``calibrate_camera`` fits; the others are held at zero."""

_TERM = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
"""cornerSubPix stop rule of OpenCV's calibration sample: 30 iterations or a step < 0.01 px."""

# -- pairs by name ----------------------------------------------------------------------------


@dataclass(frozen=True)
class ImagePair:
    """One pose: the depth camera's image (IR or colour) and the thermal image."""

    name: str
    depth_path: Path
    thermal_path: Path


@dataclass(frozen=True)
class PairListing:
    """What :func:`discover_pairs` found: matched pairs and files left out, with why."""

    pairs: tuple[ImagePair, ...]
    unmatched: tuple[tuple[Path, str], ...]


_SUFFIX_RULE = re.compile(rf"(?P<stem>.+)_(?P<role>{'|'.join(DEPTH_ROLES)}|thermal)", re.IGNORECASE)
_SIDE_RULE = re.compile(r"(?P<role>left|right)(?P<stem>.*)", re.IGNORECASE)
RULES_TEXT = "<stem>_ir|_color|_rgb + <stem>_thermal, or left<key> + right<key>"


def discover_pairs(pairs_dir: str | Path) -> PairListing:
    """Match the images of ``pairs_dir`` into pairs by name.

    Two rules (any image extension of :data:`IMAGE_SUFFIXES`, case-insensitive):

    - ``<stem>_ir.<ext>`` (or ``_color`` / ``_rgb``) with ``<stem>_thermal.<ext>``;
    - ``left<key>.<ext>`` with ``right<key>.<ext>`` (OpenCV's stereo samples): left is the
      depth camera's image, right the thermal image.

    Images that fit no rule, lack a partner, or duplicate a role of a stem (``a_ir.png`` and
    ``a_ir.npy``) are listed in ``unmatched`` with the reason; other files are ignored.
    Pairs are sorted by name. Raises InputError if the folder is missing or has no pair.
    """
    folder = Path(pairs_dir)
    if not folder.is_dir():
        raise InputError(f"{folder}: not a folder of image pairs")
    roles: dict[tuple[str, str], dict[str, Path]] = {}
    unmatched: list[tuple[Path, str]] = []
    for path in sorted(folder.iterdir()):
        if not path.is_file() or path.suffix.lower() not in IMAGE_SUFFIXES:
            continue
        stem = path.stem
        m = _SUFFIX_RULE.fullmatch(stem)
        if m:
            key = ("suffix", m.group("stem"))
            role = "thermal" if m.group("role").lower() == "thermal" else "depth"
        elif m2 := _SIDE_RULE.fullmatch(stem):
            key = ("side", m2.group("stem"))
            role = "depth" if m2.group("role").lower() == "left" else "thermal"
        else:
            unmatched.append((path, f"name fits no rule ({RULES_TEXT})"))
            continue
        slot = roles.setdefault(key, {})
        if role in slot:
            unmatched.append((path, f"{slot[role].name} already is the {role} image"))
            continue
        slot[role] = path
    pairs = []
    for (rule, stem), slot in roles.items():
        if "depth" in slot and "thermal" in slot:
            name = stem if rule == "suffix" else (stem or "(blank)")
            pairs.append(ImagePair(name, slot["depth"], slot["thermal"]))
            continue
        ((role, path),) = slot.items()
        want = "thermal" if role == "depth" else "depth camera (IR/colour)"
        if rule == "side":
            hint = f"{'right' if role == 'depth' else 'left'}{stem}.*"
        elif role == "depth":
            hint = f"{stem}_thermal.*"
        else:
            hint = f"{stem}_ir.* (or _color, _rgb)"
        unmatched.append((path, f"no {want} image to pair with (expected {hint})"))
    if not pairs:
        raise InputError(f"{folder}: no image pairs found (naming rules: {RULES_TEXT})")
    pairs.sort(key=lambda p: (p.name, str(p.depth_path)))
    unmatched.sort(key=lambda u: str(u[0]))
    return PairListing(tuple(pairs), tuple(unmatched))


# -- images -----------------------------------------------------------------------------------


def load_image(path: str | Path) -> NDArray[Any]:
    """A 2-D image (H, W) in its own dtype (uint8, uint16 counts, float) from PNG, TIFF,
    JPEG, BMP, PGM or ``.npy``; colour images become grey. Raises InputError naming the file
    when it cannot be read or is not one image."""
    p = Path(path)
    if p.suffix.lower() == ".npy":
        try:
            img = np.load(p, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise InputError(f"{p}: unreadable .npy ({str(exc).splitlines()[0]})") from None
        if img.ndim == 3 and img.shape[2] == 1:
            img = img[..., 0]
        if img.ndim == 3 and img.shape[2] in (3, 4) and img.dtype in (np.uint8, np.uint16):
            img = cv2.cvtColor(
                img, cv2.COLOR_RGB2GRAY if img.shape[2] == 3 else cv2.COLOR_RGBA2GRAY
            )
        numeric = np.issubdtype(img.dtype, np.integer) or np.issubdtype(img.dtype, np.floating)
        if img.ndim != 2 or not numeric:
            raise InputError(f"{p}: expected a 2-D numeric image, got {img.dtype} {img.shape}")
        return np.asarray(img)
    try:
        data = np.frombuffer(p.read_bytes(), dtype=np.uint8)
    except OSError as exc:
        raise InputError(f"{p}: unreadable ({exc.strerror or exc})") from None
    # a truncated file is ours to report, in one line: OpenCV's own warning would be a second
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    try:
        raw = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    finally:
        cv2.utils.logging.setLogLevel(level)
    if raw is None or raw.size == 0:
        raise InputError(f"{p}: unreadable (not an image OpenCV can decode)")
    img = np.asarray(raw)
    if img.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        img = cv2.cvtColor(img, code)
    return img


def stretch_to_unit(
    image: NDArray[Any], low_pct: float = 1.0, high_pct: float = 99.5
) -> NDArray[np.float32] | None:
    """Affine map of an image to 0..255 by its percentiles (float32, not clipped).

    The ``low_pct`` percentile maps to 0 and ``high_pct`` to 255: robust to hot or dead pixels
    and to a 14-bit thermal image whose board spans a few hundred counts. Values outside the
    range are kept (clipping happens only for 8-bit detection), so corner refinement sees
    the image's real gradients. NaNs become the median. None when the image is flat.
    """
    f = image.astype(np.float32)
    if np.issubdtype(image.dtype, np.floating):
        finite = np.isfinite(f)
        if not finite.any():
            return None
        f = np.where(finite, f, np.median(f[finite])).astype(np.float32)
    lo, hi = np.percentile(f, [low_pct, high_pct])
    if not hi > lo:
        lo, hi = float(f.min()), float(f.max())
        if not hi > lo:
            return None
    return ((f - lo) * (255.0 / (hi - lo))).astype(np.float32)


def upscale_factor(shape: tuple[int, ...]) -> int:
    """Integer upscale before detection: to at least 480 px high (160x120 -> 4x).

    OpenCV's detectors look for quads and blobs a few pixels wide; a Lepton sees a 3 cm square
    at 0.7 m as 6 px. Images 480 px high or more are left as they are.
    """
    return max(1, min(8, math.ceil(480 / shape[0])))


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
) -> Detection | None:
    """Find ``board`` in one image; None when it is not found.

    image: (H, W) any dtype. stretch: percentile stretch (:func:`stretch_to_unit`) before
    detection; by default for every image but uint8 ones, which are used as they are.
    upscale: integer factor (default :func:`upscale_factor`); cubic interpolation, then
    points map back as u = (u_up + 0.5) / s - 0.5 (pixel centres at integers). refine:
    ``cornersubpix`` or ``homography`` (:data:`REFINE_METHODS`).

    Checkerboards: ``cv2.findChessboardCorners`` (adaptive threshold; histogram
    equalisation only for unstretched images) on the 8-bit image and its negative, then
    ``cv2.findChessboardCornersSB`` at native scale as a fallback. Corners are refined with
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
        _find_checkerboard(img8, fine, board, s, stretch)
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
    img8: NDArray[np.uint8], fine: NDArray[np.float32], board: BoardSpec, s: int, stretched: bool
) -> tuple[FloatArray, bool, str] | None:
    size = board.pattern_size
    adaptive, normalise = cv2.CALIB_CB_ADAPTIVE_THRESH, cv2.CALIB_CB_NORMALIZE_IMAGE
    fast = cv2.CALIB_CB_FAST_CHECK  # rejects images without a board quickly; same corners
    # A stretched image is normalised already: equalising its histogram again blows up the
    # noise of a uniform background (a thermal scene is mostly wall) and breaks the quads
    # (measured on simulated Lepton views: 20 of 20 found without it, 16 with it).
    tries = [adaptive, adaptive | normalise]
    if not stretched:  # OpenCV's default flags first: what its calibration sample uses
        tries.reverse()
    for flags in tries:
        for inverted in (False, True):
            ok, c = cv2.findChessboardCorners(
                255 - img8 if inverted else img8, size, flags=flags | fast
            )
            if ok:
                return _refine(c, fine, board, s), inverted, "findChessboardCorners"
    # the sector-based detector copes with blur at native scale
    native = (
        img8 if s == 1 else cv2.resize(img8, None, fx=1 / s, fy=1 / s, interpolation=cv2.INTER_AREA)
    )
    sb = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    for inverted in (False, True):
        ok, c = cv2.findChessboardCornersSB(255 - native if inverted else native, size, flags=sb)
        if ok:
            up = (c.reshape(-1, 2).astype(np.float64) + 0.5) * s - 0.5
            return _refine(up, fine, board, s), inverted, "findChessboardCornersSB"
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


# Past the last inner corner of a checkerboard lie its outer squares on one side and the
# margin on the other: half a corner's contrast. A grid of more corners than the detector was
# told goes on with a full one there (OpenCV finds such sub-grids and would pair different
# corners in the two cameras).
CONTINUES_FRACTION = 0.7
"""Contrast past an edge, as a fraction of the inner corners', above which the pattern is
taken to go on (theory: 0.5 at a true edge, 1.0 where it goes on; measured: the highest edge
of a view 0.47-0.57 at the right size, mostly 0.66-1.15 for a sub-grid, on OpenCV's samples
and simulated IR + Lepton views; docs/calibration.md)."""


def grid_continues(image: NDArray[Any], points_px: FloatArray, board: BoardSpec) -> tuple[str, ...]:
    """The edges (``"left"``, ``"right"``, ``"top"``, ``"bottom"`` of the grid as detected)
    past which a checkerboard's corner pattern goes on: the board has more corners than
    ``board`` says.

    image: (H, W), any dtype (the score is invariant to an affine map of intensity);
    points_px: (rows * cols, 2) detected corners in grid order. A corner's contrast is the
    difference of the mean intensities of its two diagonal pairs of quadrants (3 x 3 samples
    each, 0.15-0.35 of a square from the corner along the local grid axes), signed by the
    corner's parity. The points one step past each edge (extrapolated along the grid lines)
    are scored the same, and their median is compared with the inner corners'
    (:data:`CONTINUES_FRACTION`). Edges with fewer than two such points inside the image are
    not judged.
    """
    img = np.asarray(image, dtype=np.float32)
    h, w = img.shape
    rows, cols = board.rows, board.cols
    g = np.asarray(points_px, dtype=np.float64).reshape(rows, cols, 2)
    # the grid grown by one extrapolated column on each side, and by one row on each side
    wide = np.concatenate([2 * g[:, :1] - g[:, 1:2], g, 2 * g[:, -1:] - g[:, -2:-1]], axis=1)
    tall = np.concatenate([2 * g[:1] - g[1:2], g, 2 * g[-1:] - g[-2:-1]], axis=0)
    steps = np.array([0.15, 0.25, 0.35])
    fx, fy = (a.ravel() for a in np.meshgrid(steps, steps))

    def contrast(grid: FloatArray, first_col: int, first_row: int) -> tuple[FloatArray, ...]:
        # signed corner contrast at every point of a grid, and how far its samples reach
        ex = np.gradient(grid, axis=1)[..., None, :]
        ey = np.gradient(grid, axis=0)[..., None, :]
        means = []
        for sx, sy in ((1, 1), (-1, -1), (1, -1), (-1, 1)):
            q = grid[..., None, :] + (sx * fx)[:, None] * ex + (sy * fy)[:, None] * ey
            means.append(map_coordinates(img, [q[..., 1], q[..., 0]], order=1).mean(axis=-1))
        r, c = np.indices(grid.shape[:2])
        parity = np.where((r + first_row + c + first_col) % 2 == 0, 1.0, -1.0)
        reach = 0.35 * (np.abs(ex) + np.abs(ey)).max(axis=(-2, -1))
        return (means[0] + means[1] - means[2] - means[3]) * parity, reach

    inner = float(np.median(contrast(g, 0, 0)[0]))
    if not np.isfinite(inner) or inner == 0:
        return ()
    wide_c, wide_reach = contrast(wide, -1, 0)
    tall_c, tall_reach = contrast(tall, 0, -1)
    found = []
    for name, grid, score, reach, pick in (
        ("left", wide, wide_c, wide_reach, np.s_[:, 0]),
        ("right", wide, wide_c, wide_reach, np.s_[:, -1]),
        ("top", tall, tall_c, tall_reach, np.s_[0, :]),
        ("bottom", tall, tall_c, tall_reach, np.s_[-1, :]),
    ):
        p, m = grid[pick], reach[pick] + 1
        inside = (p[:, 0] >= m) & (p[:, 0] <= w - 1 - m) & (p[:, 1] >= m) & (p[:, 1] <= h - 1 - m)
        if inside.sum() >= 2 and np.median(score[pick][inside]) / inner > CONTINUES_FRACTION:
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


# -- calibration ------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class CameraFit:
    """One camera's intrinsics from the board views, or given and held fixed.

    rms_px: RMS reprojection error over all points; per_view_rms_px (n,): per image;
    rvecs, tvecs: ``camera_from_board`` per view (Rodrigues rotation and translation as (3,)
    arrays, metres);
    model: distortion model name (:data:`DISTORTION_MODELS`) or ``"fixed"``;
    std_px: standard deviations of fx, fy, cx, cy from OpenCV (NaN when fixed).
    """

    intrinsics: Intrinsics
    rms_px: float
    per_view_rms_px: FloatArray
    rvecs: tuple[FloatArray, ...]
    tvecs: tuple[FloatArray, ...]
    model: str
    std_px: FloatArray = field(default_factory=lambda: np.full(4, np.nan))


def _f32(points: FloatArray) -> NDArray[np.float32]:
    return np.ascontiguousarray(points, dtype=np.float32).reshape(-1, 1, points.shape[-1])


def _view_rms(
    obj: FloatArray, img: FloatArray, rvec: FloatArray, tvec: FloatArray, intr: Intrinsics
) -> float:
    proj, _ = cv2.projectPoints(obj, rvec, tvec, intr.matrix, intr.distortion.copy())
    return float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1))))


def calibrate_camera(
    object_points: Sequence[FloatArray],
    image_points: Sequence[FloatArray],
    image_size: tuple[int, int],
    model: str = "full",
) -> CameraFit:
    """Intrinsics of one camera from board views (``cv2.calibrateCamera``, Zhang's method).

    object_points: per view (N, 3) board points in metres; image_points: per view (N, 2)
    pixels; image_size: (width, height); model: which distortion terms to fit
    (:data:`DISTORTION_MODELS`).
    """
    if model not in DISTORTION_MODELS:
        raise InputError(
            f"unknown distortion model {model!r}; choose from {list(DISTORTION_MODELS)}"
        )
    rms, k, dist, rvecs, tvecs, std_intr, _, per_view = cv2.calibrateCameraExtended(
        [_f32(o) for o in object_points],
        [_f32(p) for p in image_points],
        image_size,
        np.eye(3),
        np.zeros(5),
        flags=DISTORTION_MODELS[model],
    )
    d = np.zeros(5)
    flat = np.asarray(dist, dtype=np.float64).ravel()
    d[: min(5, flat.size)] = flat[:5]
    w, h = image_size
    intr = Intrinsics(w, h, float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]), d)
    return CameraFit(
        intr,
        float(rms),
        np.asarray(per_view, dtype=np.float64).ravel(),
        tuple(np.asarray(r, np.float64).ravel() for r in rvecs),
        tuple(np.asarray(t, np.float64).ravel() for t in tvecs),
        model,
        np.asarray(std_intr, dtype=np.float64).ravel()[:4],
    )


def fixed_camera_fit(
    intrinsics: Intrinsics,
    object_points: Sequence[FloatArray],
    image_points: Sequence[FloatArray],
) -> CameraFit:
    """Board poses and reprojection errors of a camera whose intrinsics are given
    (``cv2.solvePnP``, iterative, per view); shapes as :func:`calibrate_camera`."""
    rvecs, tvecs, per_view, sq = [], [], [], []
    for obj, img in zip(object_points, image_points, strict=True):
        ok, rvec, tvec = cv2.solvePnP(
            obj.astype(np.float64),
            img.astype(np.float64),
            intrinsics.matrix,
            intrinsics.distortion.copy(),
        )
        if not ok:  # pragma: no cover - solvePnP fails only on degenerate input
            raise InputError("solvePnP failed for a view with the given depth intrinsics")
        rvec = np.asarray(rvec, np.float64).ravel()
        tvec = np.asarray(tvec, np.float64).ravel()
        rvecs.append(rvec)
        tvecs.append(tvec)
        e = _view_rms(obj, img, rvec, tvec, intrinsics)
        per_view.append(e)
        sq.append(e * e * len(obj))
    n = sum(len(o) for o in object_points)
    return CameraFit(
        intrinsics,
        float(np.sqrt(sum(sq) / n)),
        np.array(per_view),
        tuple(rvecs),
        tuple(tvecs),
        "fixed",
    )


@dataclass(frozen=True, eq=False)
class StereoFit:
    """``thermal_from_depth`` from ``cv2.stereoCalibrate`` with fixed intrinsics.

    rms_px: OpenCV's RMS over both cameras' points; per_view_rms_px (n, 2): per pair, depth
    camera then thermal camera.
    """

    thermal_from_depth: RigidTransform
    rms_px: float
    per_view_rms_px: FloatArray

    @property
    def baseline_m(self) -> float:
        """Distance between the optical centres, metres."""
        return self.thermal_from_depth.distance_m

    @property
    def rotation_deg(self) -> float:
        """Angle of the rotation between the cameras, degrees."""
        return self.thermal_from_depth.angle_deg


def stereo_calibrate(
    object_points: Sequence[FloatArray],
    depth_points: Sequence[FloatArray],
    thermal_points: Sequence[FloatArray],
    depth: Intrinsics,
    thermal: Intrinsics,
) -> StereoFit:
    """The rigid transform p_thermal = R p_depth + t (t in the board's units: metres) with
    both cameras' intrinsics fixed (``cv2.stereoCalibrate``, ``CALIB_FIX_INTRINSIC``).

    object_points: per pair (N, 3) metres; depth_points / thermal_points: per pair (N, 2) px
    in matching order (:func:`match_order`).
    """
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-7)
    out = cv2.stereoCalibrateExtended(
        [_f32(o) for o in object_points],
        [_f32(p) for p in depth_points],
        [_f32(p) for p in thermal_points],
        depth.matrix,
        depth.distortion.copy(),
        thermal.matrix,
        thermal.distortion.copy(),
        (depth.width, depth.height),
        np.eye(3),
        np.zeros((3, 1)),
        flags=cv2.CALIB_FIX_INTRINSIC,
        criteria=crit,
    )
    rms, r, t, per_view = out[0], out[5], out[6], out[11]
    transform = RigidTransform(
        np.asarray(r, np.float64), np.asarray(t, np.float64).ravel(), "thermal", "depth"
    )
    return StereoFit(transform, float(rms), np.asarray(per_view, dtype=np.float64).reshape(-1, 2))


# -- outliers and coverage --------------------------------------------------------------------

OUTLIER_MAD_K = 3.0
OUTLIER_MEDIAN_RATIO = 2.0


def flag_outliers(errors_px: FloatArray) -> NDArray[np.bool_]:
    """Outlier images by their RMS reprojection error, per column (camera) of
    ``errors_px`` (n,) or (n, k); True where any column flags the row.

    Rule: e > median + 3 x 1.4826 x MAD (MAD scaled to a normal distribution's sigma) and
    e > 2 x median (``OUTLIER_MEDIAN_RATIO``): the first flags what is far off the spread of
    the others, the second keeps images that are only a little worse when all errors are
    alike (MAD near 0)."""
    e = np.asarray(errors_px, dtype=np.float64)
    e = e[:, None] if e.ndim == 1 else e
    out: NDArray[np.bool_] = np.any(e > outlier_limits_px(e), axis=1)
    return out


def per_view_errors_px(depth: CameraFit, thermal: CameraFit, stereo: StereoFit) -> FloatArray:
    """Per-image RMS reprojection errors (n, 4), pixels: each camera's own fit, then the
    stereo fit's depth and thermal sides (the columns the outlier rule judges)."""
    return np.column_stack([depth.per_view_rms_px, thermal.per_view_rms_px, stereo.per_view_rms_px])


def outlier_limits_px(errors_px: FloatArray) -> FloatArray:
    """The thresholds of :func:`flag_outliers` per column, pixels."""
    e = np.asarray(errors_px, dtype=np.float64)
    if e.ndim == 1:
        e = e[:, None]
    med = np.median(e, axis=0)
    mad = 1.4826 * np.median(np.abs(e - med), axis=0)
    out: FloatArray = np.maximum(med + OUTLIER_MAD_K * mad, OUTLIER_MEDIAN_RATIO * med)
    return out


def coverage_grid(
    points_px: FloatArray, width: int, height: int, cols: int = 8
) -> NDArray[np.int64]:
    """Count of detected points per cell of a grid over the image, (rows, cols).

    The grid has ``cols`` columns and round(cols x height / width) rows (8 x 6 for 4:3):
    cells of 20 x 20 px on a 160x120 thermal image.
    """
    rows = max(1, round(cols * height / width))
    pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
    counts, _, _ = np.histogram2d(
        pts[:, 1], pts[:, 0], bins=(rows, cols), range=((-0.5, height - 0.5), (-0.5, width - 0.5))
    )
    return counts.astype(np.int64)


# -- the whole run ----------------------------------------------------------------------------


SkipKind = Literal["unreadable", "no board", "larger board"]


@dataclass(frozen=True)
class SkippedPair:
    """A pair left out: of which kind (``"unreadable"``, ``"no board"``, ``"larger board"``:
    a board with more corners than asked for), why in words, and which files are to blame."""

    pair: ImagePair
    kind: SkipKind
    reason: str
    files: tuple[Path, ...]


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """Everything :func:`run_calibration` found: the calibration, the fits, the pairs used,
    skipped and dropped, the outlier flags and the detections (for coverage)."""

    calibration: Calibration
    board: BoardSpec
    depth_fit: CameraFit
    thermal_fit: CameraFit
    stereo: StereoFit
    used: tuple[ImagePair, ...]
    depth_points: tuple[FloatArray, ...]
    thermal_points: tuple[FloatArray, ...]
    thermal_inverted: tuple[bool, ...]
    dropped: tuple[ImagePair, ...]
    skipped: tuple[SkippedPair, ...]
    unmatched: tuple[tuple[Path, str], ...]

    @cached_property
    def errors_px(self) -> FloatArray:
        """Per-image RMS reprojection errors (n, 4): depth, thermal, stereo depth and thermal
        sides (:func:`per_view_errors_px`)."""
        return per_view_errors_px(self.depth_fit, self.thermal_fit, self.stereo)

    @cached_property
    def outliers(self) -> NDArray[np.bool_]:
        """The used images :func:`flag_outliers` flags."""
        return flag_outliers(self.errors_px)

    @cached_property
    def warnings(self) -> tuple[str, ...]:
        """What the user should know: poor thermal coverage, few pairs, outlier images."""
        warn = []
        cov = float(np.mean(self.thermal_coverage > 0))
        if cov < 0.5:
            warn.append(
                f"the board covered {cov:.0%} of the thermal image: add poses near its edges "
                "and corners, or distortion is extrapolated there"
            )
        if len(self.used) < 10:
            warn.append(f"only {len(self.used)} pairs used: 15-25 well-spread poses fit better")
        if self.outliers.any():
            names = ", ".join(p.name for p, f in zip(self.used, self.outliers, strict=True) if f)
            warn.append(f"outlier images: {names} (--drop-outliers fits without them)")
        return tuple(warn)

    def per_image(self) -> list[dict[str, Any]]:
        """Per used pair: name, depth / thermal RMS (own fits), stereo RMS per camera,
        outlier flag."""
        rows = []
        for i, pair in enumerate(self.used):
            rows.append(
                {
                    "name": pair.name,
                    "depth_file": pair.depth_path.name,
                    "thermal_file": pair.thermal_path.name,
                    "depth_rms_px": float(self.depth_fit.per_view_rms_px[i]),
                    "thermal_rms_px": float(self.thermal_fit.per_view_rms_px[i]),
                    "stereo_depth_rms_px": float(self.stereo.per_view_rms_px[i, 0]),
                    "stereo_thermal_rms_px": float(self.stereo.per_view_rms_px[i, 1]),
                    "thermal_inverted": bool(self.thermal_inverted[i]),
                    "outlier": bool(self.outliers[i]),
                }
            )
        return rows

    @property
    def thermal_coverage(self) -> NDArray[np.int64]:
        t = self.calibration.thermal
        return coverage_grid(np.concatenate(self.thermal_points), t.width, t.height)

    @property
    def depth_coverage(self) -> NDArray[np.int64]:
        d = self.calibration.depth
        return coverage_grid(np.concatenate(self.depth_points), d.width, d.height)

    def report_dict(self) -> dict[str, Any]:
        """All figures of the report, JSON-ready (pixels, millimetres, degrees)."""
        cal = self.calibration
        t = cal.thermal_from_depth
        cov_t, cov_d = self.thermal_coverage, self.depth_coverage
        return {
            "board": str(self.board),
            "square_m": self.board.spacing_m,
            "pairs_used": len(self.used),
            "depth_camera": _camera_report(self.depth_fit),
            "thermal_camera": _camera_report(self.thermal_fit),
            "stereo": {
                "rms_px": self.stereo.rms_px,
                "baseline_mm": self.stereo.baseline_m * 1000.0,
                "translation_mm": (t.translation_m * 1000.0).tolist(),
                "rotation_deg": self.stereo.rotation_deg,
                "rotation": t.rotation.tolist(),
            },
            "outlier_rule": (
                f"per-image RMS > max(median + {OUTLIER_MAD_K:g} x 1.4826 x MAD, "
                f"{OUTLIER_MEDIAN_RATIO:g} x median), per camera, own fits and stereo"
            ),
            "outlier_limits_px": dict(
                zip(
                    ["depth", "thermal", "stereo_depth", "stereo_thermal"],
                    outlier_limits_px(self.errors_px).tolist(),
                    strict=True,
                )
            ),
            "per_image": self.per_image(),
            "dropped_outliers": [p.name for p in self.dropped],
            "coverage": {
                "thermal_fraction": float(np.mean(cov_t > 0)),
                "thermal_cells": cov_t.tolist(),
                "depth_fraction": float(np.mean(cov_d > 0)),
                "depth_cells": cov_d.tolist(),
            },
            "skipped": [
                {"name": s.pair.name, "reason": s.reason, "files": [str(f) for f in s.files]}
                for s in self.skipped
            ],
            "unmatched": [{"file": str(p), "reason": r} for p, r in self.unmatched],
            "warnings": list(self.warnings),
        }


def _camera_report(fit: CameraFit) -> dict[str, Any]:
    intr = fit.intrinsics
    cx0, cy0 = (intr.width - 1) / 2.0, (intr.height - 1) / 2.0
    return {
        "size": [intr.width, intr.height],
        "model": fit.model,
        "rms_px": fit.rms_px,
        "fx": intr.fx,
        "fy": intr.fy,
        "cx": intr.cx,
        "cy": intr.cy,
        "distortion": intr.distortion.tolist(),
        "std_fx_fy_cx_cy_px": [None if np.isnan(v) else float(v) for v in fit.std_px],
        "principal_point_offset_px": [intr.cx - cx0, intr.cy - cy0],
        "hfov_deg": intr.hfov_deg,
    }


def load_depth_intrinsics(path: str | Path) -> tuple[Intrinsics, float | None]:
    """Depth camera intrinsics to hold fixed, and its depth unit if the file has one.

    Accepts a calibration file (its ``depth:`` section is used) or a YAML/JSON file with just
    the camera's fields (width, height, fx, fy, cx, cy, distortion, optional depth_scale_m).
    """
    data = read_mapping(path)
    nested = isinstance(data.get("depth"), dict)
    section = data["depth"] if nested else data
    schema = DepthCameraSchema if "depth_scale_m" in section else CameraSchema
    try:
        cam = schema.model_validate(section)
    except ValidationError as exc:
        where = "depth." if nested else ""
        raise InputError(f"{path}: {where}{describe_validation_error(exc)}") from None
    return intrinsics_of(cam), getattr(cam, "depth_scale_m", None)


def _image_size(img: NDArray[Any]) -> tuple[int, int]:
    return (int(img.shape[1]), int(img.shape[0]))


def _check_sizes(sizes: dict[Path, tuple[int, int]], camera: str) -> tuple[int, int]:
    """The one image size of a camera; InputError naming the files that differ."""
    counts = Counter(sizes.values())
    common, n_common = counts.most_common(1)[0]
    odd = [(p, s) for p, s in sizes.items() if s != common]
    if odd:
        shown = ", ".join(f"{p.name} is {s[0]}x{s[1]}" for p, s in odd[:3])
        more = f" and {len(odd) - 3} more" if len(odd) > 3 else ""
        raise InputError(
            f"{camera} image sizes differ: {shown}{more}, but {n_common} "
            f"{'is' if n_common == 1 else 'are'} {common[0]}x{common[1]}"
        )
    return common


def run_calibration(
    pairs: str | Path | PairListing,
    board: BoardSpec,
    depth_intrinsics: Intrinsics | None = None,
    depth_scale_m: float = 0.001,
    thermal_model: str = "no-k3",
    depth_model: str = "radial",
    drop_outliers: bool = False,
    min_pairs: int = MIN_PAIRS,
    thermal_upscale: int | None = None,
    thermal_refine: str = "homography",
    depth_refine: str = "cornersubpix",
    progress: Progress | None = None,
) -> CalibrationResult:
    """Calibrate the pair from the image pairs of a folder (or what :func:`discover_pairs`
    found in one).

    board: the target (square size in metres: translation comes out in metres);
    depth_intrinsics: hold the depth camera's intrinsics fixed (else calibrated from its
    images); depth_scale_m: the depth unit written to the calibration file; thermal_model /
    depth_model: distortion terms to fit (:data:`DISTORTION_MODELS`); drop_outliers: fit
    again without the outlier images (:func:`flag_outliers`); min_pairs: fewest usable pairs;
    progress: called with 1 per pair examined.

    Unreadable images and pairs where one camera shows no board are skipped and listed.
    Raises InputError for fewer than ``min_pairs`` usable pairs (saying how many and why),
    image sizes that change within a camera, or depth intrinsics of another image size.
    """
    for name, refine in (("thermal", thermal_refine), ("depth", depth_refine)):
        if refine not in REFINE_METHODS:
            raise InputError(
                f"--{name}-refine: unknown {refine!r}; choose from {', '.join(REFINE_METHODS)}"
            )
    for name, model in (("thermal", thermal_model), ("depth", depth_model)):
        if model not in DISTORTION_MODELS:
            raise InputError(
                f"--{name}-model: unknown {model!r}; choose from {', '.join(DISTORTION_MODELS)}"
            )
    listing = pairs if isinstance(pairs, PairListing) else discover_pairs(pairs)
    skipped: list[SkippedPair] = []
    # first read every image (cheap), so that a change of image size stops the run before
    # the slow detection
    loaded: list[tuple[ImagePair, NDArray[Any], NDArray[Any]]] = []
    depth_sizes: dict[Path, tuple[int, int]] = {}
    thermal_sizes: dict[Path, tuple[int, int]] = {}
    for pair in listing.pairs:
        images = []
        for path in (pair.depth_path, pair.thermal_path):
            try:
                images.append(load_image(path))
            except InputError as exc:
                skipped.append(SkippedPair(pair, "unreadable", str(exc), (path,)))
                break
        else:
            depth_sizes[pair.depth_path] = _image_size(images[0])
            thermal_sizes[pair.thermal_path] = _image_size(images[1])
            loaded.append((pair, images[0], images[1]))
    depth_size = _check_sizes(depth_sizes, "depth camera") if depth_sizes else (0, 0)
    thermal_size = _check_sizes(thermal_sizes, "thermal") if thermal_sizes else (0, 0)
    if (
        depth_intrinsics is not None
        and depth_sizes
        and (depth_intrinsics.width, depth_intrinsics.height) != depth_size
    ):
        raise InputError(
            f"--depth-intrinsics: size {depth_intrinsics.width}x{depth_intrinsics.height} does not "
            f"match the depth camera's images ({depth_size[0]}x{depth_size[1]})"
        )
    if progress and len(loaded) < len(listing.pairs):
        progress(len(listing.pairs) - len(loaded))

    found: list[tuple[ImagePair, Detection, Detection]] = []
    for pair, depth_img, thermal_img in loaded:
        d = detect_board(depth_img, board, refine=depth_refine)
        t = detect_board(
            thermal_img, board, stretch=True, upscale=thermal_upscale, refine=thermal_refine
        )
        if d is None or t is None:
            missing = tuple(
                p for p, det in ((pair.depth_path, d), (pair.thermal_path, t)) if det is None
            )
            names = " and ".join(p.name for p in missing)
            skipped.append(SkippedPair(pair, "no board", f"no {board} found in {names}", missing))
        elif larger := _larger_boards(
            board, (pair.depth_path, depth_img, d), (pair.thermal_path, thermal_img, t)
        ):
            names = " and ".join(f"{p.name} ({', '.join(edges)})" for p, edges in larger)
            skipped.append(
                SkippedPair(
                    pair,
                    "larger board",
                    f"the pattern goes on past the edge of the {board} found in {names}",
                    tuple(p for p, _ in larger),
                )
            )
        else:
            t = Detection(
                match_order(d.points_px, t.points_px, board), t.inverted, t.upscale, t.method
            )
            found.append((pair, d, t))
        if progress:
            progress(1)
    skipped.sort(key=lambda sp: listing.pairs.index(sp.pair))
    if len(found) < min_pairs:
        raise InputError(
            _too_few_message(len(found), len(listing.pairs), min_pairs, skipped, listing, board)
        )

    def fit(
        rows: list[tuple[ImagePair, Detection, Detection]],
    ) -> tuple[CameraFit, CameraFit, StereoFit]:
        obj = [board.object_points_m() for _ in rows]
        dp = [r[1].points_px for r in rows]
        tp = [r[2].points_px for r in rows]
        if depth_intrinsics is None:
            dfit = calibrate_camera(obj, dp, depth_size, depth_model)
        else:
            dfit = fixed_camera_fit(depth_intrinsics, obj, dp)
        tfit = calibrate_camera(obj, tp, thermal_size, thermal_model)
        sfit = stereo_calibrate(obj, dp, tp, dfit.intrinsics, tfit.intrinsics)
        return dfit, tfit, sfit

    rows = found
    dfit, tfit, sfit = fit(rows)
    flags = flag_outliers(per_view_errors_px(dfit, tfit, sfit))
    dropped: tuple[ImagePair, ...] = ()
    if drop_outliers and flags.any():
        keep = [r for r, f in zip(rows, flags, strict=True) if not f]
        dropped = tuple(r[0] for r, f in zip(rows, flags, strict=True) if f)
        if len(keep) < min_pairs:
            raise InputError(
                f"--drop-outliers would leave {len(keep)} pairs (need at least {min_pairs}); "
                f"outliers: {', '.join(p.name for p in dropped)}"
            )
        rows = keep
        dfit, tfit, sfit = fit(rows)

    calibration = Calibration(
        dfit.intrinsics, tfit.intrinsics, depth_scale_m, sfit.thermal_from_depth
    )
    return CalibrationResult(
        calibration=calibration,
        board=board,
        depth_fit=dfit,
        thermal_fit=tfit,
        stereo=sfit,
        used=tuple(r[0] for r in rows),
        depth_points=tuple(r[1].points_px for r in rows),
        thermal_points=tuple(r[2].points_px for r in rows),
        thermal_inverted=tuple(r[2].inverted for r in rows),
        dropped=dropped,
        skipped=tuple(skipped),
        unmatched=listing.unmatched,
    )


def _larger_boards(
    board: BoardSpec, *views: tuple[Path, NDArray[Any], Detection]
) -> list[tuple[Path, tuple[str, ...]]]:
    """The images of a pair whose checkerboard goes on past the corners found, and where."""
    if board.kind != "checkerboard":
        return []
    found = [(path, grid_continues(img, det.points_px, board)) for path, img, det in views]
    return [(path, edges) for path, edges in found if edges]


def _too_few_message(
    n_found: int,
    n_pairs: int,
    need: int,
    skipped: list[SkippedPair],
    listing: PairListing,
    board: BoardSpec,
) -> str:
    unreadable, no_board, larger = (
        [s.pair.name for s in skipped if s.kind == kind]
        for kind in ("unreadable", "no board", "larger board")
    )
    parts = []
    if no_board:
        parts.append(f"{len(no_board)} without a board in one or both images ({_names(no_board)})")
    if larger:
        parts.append(f"{len(larger)} where the board has more corners ({_names(larger)})")
    if larger or (n_found == 0 and len(no_board) >= 2):
        # a wrong size is more likely than bad captures
        counts = "inner corners" if board.kind == "checkerboard" else "circles"
        parts.append(f"check --board: {board} counts {counts}, columns x rows")
    if unreadable:
        parts.append(f"{len(unreadable)} with an unreadable image ({_names(unreadable)})")
    if listing.unmatched:
        parts.append(f"{len(listing.unmatched)} files not paired by name")
    reasons = "; ".join(parts) if parts else "capture more poses"
    return f"only {n_found} usable pairs of {n_pairs} (need at least {need}): {reasons}"


def _names(names: list[str], limit: int = 5) -> str:
    more = f" and {len(names) - limit} more" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more


# -- report files -----------------------------------------------------------------------------


def write_report_json(result: CalibrationResult, path: str | Path) -> None:
    """``calib_report.json``: :meth:`CalibrationResult.report_dict`."""
    write_mapping(path, result.report_dict())


def plot_report(result: CalibrationResult, path: str | Path) -> None:
    """A PNG: per-image RMS errors (bars per camera, the outlier limits as dotted lines,
    outlier images shaded red) and the thermal image's coverage by detected corners (corners
    per cell of :func:`coverage_grid` as a heat map, the corners on top)."""
    from .figures import pyplot, save_figure

    plt = pyplot()
    names = [p.name for p in result.used]
    n = len(names)
    x = np.arange(n)
    fig, (ax0, ax1) = plt.subplots(
        1, 2, figsize=(13, 5.0), gridspec_kw={"width_ratios": [max(1.2, n / 12), 1]}
    )
    series = [
        ("depth", result.depth_fit.per_view_rms_px, "tab:blue"),
        ("thermal", result.thermal_fit.per_view_rms_px, "tab:orange"),
        ("stereo, thermal side", result.stereo.per_view_rms_px[:, 1], "tab:green"),
    ]
    limits = outlier_limits_px(result.errors_px)[[0, 1, 3]]  # the columns drawn
    width = 0.27
    for k, (label, values, color) in enumerate(series):
        ax0.bar(x + (k - 1) * width, values, width, label=label, color=color)
        ax0.axhline(limits[k], color=color, linestyle=":", linewidth=1.2)
    top = max(max(float(np.max(v)) for _, v, _ in series), float(np.max(limits))) * 1.3
    for i in np.flatnonzero(result.outliers):
        ax0.axvspan(x[i] - 0.45, x[i] + 0.45, color="red", alpha=0.12)
        ax0.text(x[i], top * 0.8, "outlier", ha="center", color="red", fontsize=8, rotation=90)
    ax0.plot([], [], ":", color="grey", label="outlier limit")
    ax0.set_xticks(x, names, rotation=60, ha="right", fontsize=7)
    ax0.set_xlim(-0.6, n - 0.4)
    ax0.set_ylabel("RMS reprojection error, px")
    ax0.set_ylim(0, top)
    ax0.set_title(
        f"RMS per image (all: depth {result.depth_fit.rms_px:.3f}, thermal "
        f"{result.thermal_fit.rms_px:.3f}, stereo {result.stereo.rms_px:.3f} px)",
        fontsize=9,
    )
    ax0.legend(fontsize=7, loc="upper left", ncol=4)

    t = result.calibration.thermal
    cov = result.thermal_coverage
    im = ax1.imshow(
        cov,
        cmap="magma",
        extent=(-0.5, t.width - 0.5, t.height - 0.5, -0.5),
        interpolation="nearest",
    )
    pts = np.concatenate(result.thermal_points)
    ax1.plot(pts[:, 0], pts[:, 1], ".", color="cyan", markersize=1.5, alpha=0.6)
    ax1.plot([t.cx], [t.cy], "+", color="lime", markersize=12, label="principal point")
    ax1.set_xlim(-0.5, t.width - 0.5)
    ax1.set_ylim(t.height - 0.5, -0.5)
    ax1.set_xlabel("thermal u, px")
    ax1.set_ylabel("thermal v, px")
    ax1.set_title(
        f"thermal image coverage: {np.mean(cov > 0):.0%} of cells hold corners\n"
        f"baseline {result.stereo.baseline_m * 1000:.1f} mm, rotation "
        f"{result.stereo.rotation_deg:.2f} deg",
        fontsize=9,
    )
    ax1.legend(fontsize=7, loc="lower right")
    fig.colorbar(im, ax=ax1, label="corners per cell", fraction=0.035)
    save_figure(fig, path, dpi=110)
