"""Board detection against plain OpenCV, over the ways real boards are made: property tests
on synthetic views (styles, margins, poses, blur, palettes), then the simulated rig's boards.

A view is rendered directly (a homography from the board's plane to a 160x120 image, the
pattern and its margin, Gaussian optics blur, noise), so that hypothesis can try many.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from thermodepth.board import BoardSpec
from thermodepth.calibrate import detect_board, grid_continues
from thermodepth.palettes import PALETTES, apply_palette, to_scalar

BOARD = BoardSpec("checkerboard", 7, 5, 1.0)  # 8 x 6 squares, the grid step is the unit


def render(
    squares: tuple[int, int],
    margin_squares: float,
    levels: tuple[float, float, float, float],
    tilt: tuple[float, float],
    roll_deg: float,
    scale_px: float,
    blur_px: float,
    seed: int,
    shape: tuple[int, int] = (120, 160),
) -> np.ndarray:
    """A float view (H, W) of a board of ``squares`` (cols, rows) with a uniform margin
    ``margin_squares`` wide. levels: (first square, second square, margin, background).
    The board's centre sits at the image centre, ``scale_px`` pixels per square, tilted by
    ``tilt`` (radians about x and y) and rolled."""
    h, w = shape
    cols, rows = squares
    # board plane (x, y, 0), units of squares, centred; a pinhole camera 20 squares away
    rx, ry = tilt
    r = (
        cv2.Rodrigues(np.array([0.0, 0.0, np.radians(roll_deg)]))[0]
        @ cv2.Rodrigues(np.array([rx, 0.0, 0.0]))[0]
        @ cv2.Rodrigues(np.array([0.0, ry, 0.0]))[0]
    )
    f = scale_px * 20.0
    k = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])
    board_to_image = k @ np.column_stack([r[:, 0], r[:, 1], np.array([0, 0, 20.0])])
    image_to_board = np.linalg.inv(board_to_image)
    ss = 4  # supersampled, then averaged: each pixel's footprint
    v, u = np.mgrid[0 : h * ss, 0 : w * ss]
    pix = np.stack([(u + 0.5) / ss - 0.5, (v + 0.5) / ss - 0.5, np.ones_like(u, float)], -1)
    q = pix @ image_to_board.T
    x, y = q[..., 0] / q[..., 2] + cols / 2, q[..., 1] / q[..., 2] + rows / 2
    first, second, margin, background = levels
    inside = (x >= 0) & (x < cols) & (y >= 0) & (y < rows)
    plate = (x >= -margin_squares) & (x < cols + margin_squares)
    plate &= (y >= -margin_squares) & (y < rows + margin_squares)
    img = np.where(plate, margin, background)
    checker = (np.floor(x) + np.floor(y)) % 2 == 0
    img = np.where(inside, np.where(checker, first, second), img)
    img = img.reshape(h, ss, w, ss).mean(axis=(1, 3))
    img = cv2.GaussianBlur(img, (0, 0), blur_px) if blur_px > 0 else img
    return img + np.random.default_rng(seed).normal(0.0, 0.01 * abs(first - second), img.shape)


def as_saved(view: np.ndarray, palette: str | None) -> tuple[np.ndarray, np.ndarray]:
    """What a viewer saves (16-bit counts, or 8-bit RGB in a palette) as (what our loader
    gives, the 8-bit grey image a user hands plain OpenCV)."""
    if palette is None:
        counts = np.clip(8000 + view * 400, 0, 16383).astype(np.uint16)
        f = counts.astype(np.float64)
        grey = np.clip((f - f.min()) * 255 / max(np.ptp(f), 1), 0, 255).astype(np.uint8)
        return counts, grey
    rgb = apply_palette(view, palette)
    return to_scalar(rgb).levels, cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)


def plain_opencv(grey: np.ndarray, board: BoardSpec) -> bool:
    """Whether OpenCV, called as its samples do, finds the board (either polarity)."""
    return any(
        find(img, board.pattern_size)[0]
        for img in (grey, 255 - grey)
        for find in (cv2.findChessboardCorners, cv2.findChessboardCornersSB)
    )


views = st.fixed_dictionaries(
    {
        "margin_squares": st.floats(0.3, 2.5),
        "margin": st.sampled_from(["first", "second", "between", "hotter", "colder"]),
        "tilt": st.tuples(st.floats(-0.6, 0.6), st.floats(-0.6, 0.6)),
        "roll_deg": st.floats(-30, 30),
        "scale_px": st.floats(5.0, 9.0),
        "blur_px": st.floats(0.0, 1.6),
        "palette": st.sampled_from([None, "gray", "ironbow", "inferno", "jet"]),
        "seed": st.integers(0, 2**16),
    }
)
MARGIN = {"first": 1.0, "second": 0.0, "between": 0.5, "hotter": 1.3, "colder": -0.3}


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(view=views)
def test_a_board_of_the_size_given_is_never_refused_where_plain_opencv_finds_it(
    view: dict,  # type: ignore[type-arg]
) -> None:
    levels = (1.0, 0.0, MARGIN[view["margin"]], 0.1)
    img = render(
        (BOARD.cols + 1, BOARD.rows + 1),
        view["margin_squares"],
        levels,
        view["tilt"],
        view["roll_deg"],
        view["scale_px"],
        view["blur_px"],
        view["seed"],
    )
    loaded, grey = as_saved(img, view["palette"])
    found = detect_board(loaded, BOARD, stretch=True)
    if plain_opencv(grey, BOARD):
        assert found is not None, "plain OpenCV finds the board and we do not"
    if found is not None:  # a uniform margin is never taken for more squares
        assert grid_continues(loaded, found.points_px, BOARD) == ()


def larger_board_edges(view: dict) -> tuple[str, ...] | None:  # type: ignore[type-arg]
    """The edges past which :func:`grid_continues` sees the pattern go on, for the board
    found in a view of one with two columns and two rows more squares than the board given
    (OpenCV finds a sub-grid); None where none is found."""
    levels = (1.0, 0.0, MARGIN[view["margin"]], 0.1)
    img = render(
        (BOARD.cols + 3, BOARD.rows + 3),
        view["margin_squares"],
        levels,
        view["tilt"],
        view["roll_deg"],
        min(view["scale_px"], 7.0),
        min(view["blur_px"], 1.0),
        view["seed"],
    )
    loaded, _ = as_saved(img, view["palette"])
    found = detect_board(loaded, BOARD, stretch=True)
    return None if found is None else grid_continues(loaded, found.points_px, BOARD)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(view=views)
def test_a_larger_board_is_refused(view: dict) -> None:  # type: ignore[type-arg]
    edges = larger_board_edges(view)
    assume(edges is not None)
    assert edges != ()


@pytest.mark.xfail(
    strict=True,
    reason="known: a larger board tilted steeply at 6 px a square, its far squares 3-4 px, "
    "is taken for the board given (hypothesis found it; sampling the cells through the "
    "corners' homography fixes it but flags real, distorted boards)",
)
def test_a_larger_board_tilted_steeply_at_6_px_a_square_is_refused() -> None:
    steep = {"margin_squares": 1.0, "margin": "first", "tilt": (0.0, 0.5859375),
             "roll_deg": -15.0, "scale_px": 6.0, "blur_px": 1.0, "palette": None,
             "seed": 1}  # fmt: skip
    assert larger_board_edges(steep) != ()


@pytest.mark.parametrize("palette", PALETTES)
def test_every_known_palette_gives_back_its_levels(palette: str) -> None:
    img = render((8, 6), 1.0, (1.0, 0.0, 1.0, 0.1), (0.3, -0.2), 10.0, 7.0, 0.8, 1)
    rgb = apply_palette(img, palette)
    got = to_scalar(rgb)
    lo, hi = np.percentile(img, [1, 99])
    want = np.clip(np.rint((img - lo) * 255 / (hi - lo)), 0, 255)
    # white hot and black hot share their colours: the levels come back either way up
    if palette == "blackhot":
        want = 255 - want
    assert got.fit == 1.0
    assert np.abs(got.levels - want).max() <= 2  # palettes with near-equal neighbours
