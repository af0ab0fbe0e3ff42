"""False-colour palettes of thermal viewers: applying one to a scalar image (what viewer tools
save as 8-bit RGB) and turning such an image back into a scalar one.

A palette maps 256 levels to colours. Viewers stretch each frame's counts to those levels
(automatic gain: the frame's range, or percentiles of it) and save the colours, so the
radiometry is gone, but the order of temperatures is kept wherever the palette is known:
inverting it gives back the level of every pixel, a monotonic function of the scene's
radiance, which is all that corner detection needs.

Known palettes (:data:`PALETTES`): ``gray`` (white hot), ``blackhot`` (white cold),
``ironbow`` (black - indigo - magenta - orange - yellow - white, as thermal viewers show it;
ours is a smooth curve through those colours, so a viewer's own ironbow may differ a little),
and matplotlib's ``inferno``, ``magma``, ``plasma``, ``viridis``, ``turbo``, ``jet`` and
``hot``.
"""

from __future__ import annotations

from functools import cache
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

Palette = NDArray[np.uint8]
"""(256, 3) RGB colours, level 0 first."""

_IRONBOW_STOPS = (  # level fraction: RGB
    (0.00, (0, 0, 0)),
    (0.15, (30, 0, 110)),
    (0.32, (120, 0, 150)),
    (0.50, (200, 20, 90)),
    (0.65, (240, 90, 0)),
    (0.82, (255, 190, 20)),
    (1.00, (255, 255, 255)),
)
_MATPLOTLIB = ("inferno", "magma", "plasma", "viridis", "turbo", "jet", "hot")

PALETTES = ("gray", "blackhot", "ironbow", *_MATPLOTLIB)
"""The palettes :func:`apply_palette` draws with and :func:`to_scalar` recognises."""


@cache
def palette(name: str) -> Palette:
    """The 256 RGB colours of a palette of :data:`PALETTES` (read-only)."""
    levels = np.arange(256, dtype=np.float64)
    if name == "gray":
        rgb = np.repeat(levels[:, None], 3, axis=1)
    elif name == "blackhot":
        rgb = np.repeat(255.0 - levels[:, None], 3, axis=1)
    elif name == "ironbow":
        at = np.array([f for f, _ in _IRONBOW_STOPS]) * 255.0
        colours = np.array([c for _, c in _IRONBOW_STOPS], dtype=np.float64)
        rgb = np.stack([np.interp(levels, at, colours[:, i]) for i in range(3)], axis=1)
    elif name in _MATPLOTLIB:
        from matplotlib import colormaps

        rgb = colormaps[name](levels / 255.0)[:, :3] * 255.0
    else:
        raise ValueError(f"unknown palette {name!r}; choose from {', '.join(PALETTES)}")
    out = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
    out.setflags(write=False)
    return out


def apply_palette(
    image: NDArray[np.generic], name: str, low_pct: float = 1.0, high_pct: float = 99.0
) -> NDArray[np.uint8]:
    """An 8-bit RGB image (H, W, 3) of a scalar image (H, W), as a viewer saves it: levels
    stretched linearly from the ``low_pct`` to the ``high_pct`` percentile (automatic
    gain), clipped, then coloured with the palette ``name``."""
    f = np.asarray(image, dtype=np.float64)
    lo, hi = np.percentile(f, [low_pct, high_pct])
    level = np.clip(np.rint((f - lo) * (255.0 / max(hi - lo, 1e-9))), 0, 255).astype(np.intp)
    return palette(name)[level]


class Scalar(NamedTuple):
    """A scalar image recovered from a colour one: ``levels`` (H, W) float32, 0..255;
    ``how``: the palette inverted, ``"luminance"`` (colours of an unknown palette), and
    ``fit``: the share of pixels within a few levels of the palette's colours."""

    levels: NDArray[np.float32]
    how: str
    fit: float


_MATCH_RGB = 12.0  # RGB distance a pixel may lie from its palette colour (JPEG, resampling)
_MATCH_SHARE = 0.9  # pixels that must match for a palette to be the image's
_CURVE_RMS = 12.0  # RGB spread of pixels of one luminance, at most, in a palette image


class NotFalseColourError(ValueError):
    """A colour image that no palette made: its colours are not a function of one level."""


def to_scalar(rgb: NDArray[np.uint8]) -> Scalar:
    """The levels of a false-colour image (H, W, 3) RGB uint8.

    A known palette (:data:`PALETTES`) is inverted when at least 90 % of the pixels lie
    within 12 RGB units of its colours (lossless exports match exactly; JPEG and resampling
    move colours a little); the best-fitting one wins. Otherwise, when the colours are a
    function of one level (pixels of the same luminance share their colour, within 12 RGB
    units RMS), the luminance is the level. Otherwise the image is no palette's:
    :class:`NotFalseColourError`, saying how far the best palette got.
    """
    from scipy.spatial import cKDTree

    pixels = np.asarray(rgb, dtype=np.float64).reshape(-1, 3)
    best: Scalar | None = None
    for name in PALETTES:
        distance, index = cKDTree(palette(name).astype(np.float64)).query(pixels)
        share = float(np.mean(distance <= _MATCH_RGB))
        if best is None or share > best.fit:
            levels = index.reshape(rgb.shape[:2]).astype(np.float32)
            best = Scalar(levels, name, share)
    assert best is not None
    if best.fit >= _MATCH_SHARE:
        return best
    luminance = pixels @ np.array([0.299, 0.587, 0.114])
    level = np.rint(luminance).astype(np.intp)
    counts = np.bincount(level, minlength=256)
    mean = (
        np.stack([np.bincount(level, pixels[:, i], minlength=256) for i in range(3)], axis=1)
        / np.maximum(counts, 1)[:, None]
    )
    spread = float(np.sqrt(np.mean(np.sum((pixels - mean[level]) ** 2, axis=1))))
    if spread <= _CURVE_RMS:
        return Scalar(luminance.reshape(rgb.shape[:2]).astype(np.float32), "luminance", best.fit)
    raise NotFalseColourError(
        f"its colours are not those of a thermal palette (best: {best.how}, "
        f"{best.fit:.0%} of pixels; pixels of one brightness differ by {spread:.0f} RGB units)"
    )
