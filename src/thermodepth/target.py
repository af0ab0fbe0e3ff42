"""The reference target of a sweep (the paper's heated plate, section 4) in a thermal frame.

A target is a set of thermal pixels (a boolean (h, w) mask) chosen one of three ways
(:class:`TargetSpec`, the ``--target`` option of ``collect-sweep``):

- ``auto``: the plate found by :func:`find_plate`: the largest region that is flat in depth
  and uniform in temperature, with an apparent temperature near the reference's;
- ``rect:U0,V0,U1,V1``: thermal pixels U0 <= u < U1, V0 <= v < V1 (160x120 on a Lepton 3);
- ``depth-range:NEAR,FAR``: the largest connected region whose Z (metres, along the thermal
  camera's axis) lies in [NEAR, FAR].
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from .errors import FieldError
from .measure import DepthRangeRoi, RectRoi

FloatArray = NDArray[np.floating]
BoolArray = NDArray[np.bool_]

MIN_TARGET_PX = 9
"""Fewest thermal pixels a target may have (3x3): fewer is 'not found'."""

NEAR_REFERENCE_C = 5.0
"""How far (C) the plate's apparent temperature may be from the reference's: the distance and
VOx effects the sweep measures move a reading by a few degrees (Fig. 13 of the paper)."""

EDGE_TEMP_C = 0.5
"""A step in apparent temperature between neighbouring pixels that counts as an edge: some
ten times a Lepton's temporal noise (NETD < 50 mK), so a plate's noise and gentle gradients
are not edges, while the blur of its border (PSF) is."""

EDGE_DEPTH_FRACTION, EDGE_DEPTH_M = 0.03, 0.005
"""A step in Z between neighbouring pixels that counts as an edge: 3 % of Z plus 5 mm, above
the D435's noise (about 2 % RMS at 3 m) and the slope of a plate turned up to some 70 degrees
across one thermal pixel."""

_SPEC = re.compile(r"^(auto|rect|depth-range)(?::(.*))?$")


@dataclass(frozen=True)
class TargetSpec:
    """How the target is chosen: ``kind`` auto, rect (``rect``: u0, v0, u1, v1 thermal
    pixels) or depth-range (``depth_range_m``: near, far)."""

    kind: str = "auto"
    rect: tuple[int, int, int, int] | None = None
    depth_range_m: tuple[float, float] | None = None

    @classmethod
    def parse(cls, text: str) -> TargetSpec:
        """``auto``, ``rect:U0,V0,U1,V1`` or ``depth-range:NEAR,FAR``; a FieldError naming
        ``target`` otherwise."""
        m = _SPEC.match(text.strip())
        if m is None:
            raise FieldError(
                "target",
                f"{text!r}: expected auto, rect:U0,V0,U1,V1 (thermal pixels) or "
                "depth-range:NEAR,FAR (metres)",
            )
        kind, arg = m.group(1), m.group(2)
        if kind == "auto":
            if arg is not None:
                raise FieldError("target", f"{text!r}: auto takes no argument")
            return cls()
        parts = [] if arg is None else arg.split(",")
        if kind == "rect":
            if len(parts) != 4 or not all(re.fullmatch(r"\s*\d+\s*", p) for p in parts):
                raise FieldError("target", f"{text!r}: expected rect:U0,V0,U1,V1 (4 integers)")
            u0, v0, u1, v1 = (int(p) for p in parts)
            if not (u0 < u1 and v0 < v1):
                raise FieldError("target", f"{text!r}: expected U0 < U1 and V0 < V1")
            return cls("rect", rect=(u0, v0, u1, v1))
        try:
            near, far = (float(p) for p in parts)
        except ValueError:
            raise FieldError(
                "target", f"{text!r}: expected depth-range:NEAR,FAR (2 numbers, metres)"
            ) from None
        if not 0 <= near < far < np.inf:
            raise FieldError("target", f"{text!r}: expected 0 <= NEAR < FAR (metres)")
        return cls("depth-range", depth_range_m=(near, far))

    def __str__(self) -> str:
        if self.rect is not None:
            return "rect:" + ",".join(str(v) for v in self.rect)
        if self.depth_range_m is not None:
            return f"depth-range:{self.depth_range_m[0]:g},{self.depth_range_m[1]:g}"
        return "auto"

    def check_inside(self, shape: tuple[int, int]) -> None:
        """A rect must overlap the (h, w) thermal image (FieldError otherwise)."""
        if self.rect is not None and not RectRoi("target", *self.rect).mask(shape).any():
            h, w = shape
            raise FieldError(
                "target",
                f"{self} lies outside the {w}x{h} thermal image (u 0..{w - 1}, v 0..{h - 1})",
            )

    def find(
        self, z_m: FloatArray, temp_c: FloatArray, reference_temp_c: float
    ) -> BoolArray | None:
        """The target's thermal pixels in one frame, None when it is not there.

        z_m: (h, w) Z of each thermal pixel's surface, metres (NaN: no depth); temp_c: (h, w)
        apparent temperature, C (NaN: bad pixel). Pixels without a distance or a temperature
        are never part of it."""
        valid = np.isfinite(z_m) & np.isfinite(temp_c)
        if self.rect is not None:
            mask = RectRoi("target", *self.rect).mask(valid.shape) & valid
            return mask if mask.sum() >= MIN_TARGET_PX else None
        if self.depth_range_m is not None:
            inside = DepthRangeRoi("target", *self.depth_range_m).mask(valid.shape, z_m) & valid
            return _largest(_components(inside))
        return find_plate(z_m, temp_c, reference_temp_c)


def _components(mask: BoolArray) -> list[BoolArray]:
    """The 4-connected regions of ``mask`` of at least :data:`MIN_TARGET_PX` pixels, each as
    a mask (the smaller ones, often hundreds in a noisy frame, get none: no target is in
    them)."""
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=4)
    return [labels == k for k in range(1, n) if stats[k, cv2.CC_STAT_AREA] >= MIN_TARGET_PX]


def _largest(regions: list[BoolArray]) -> BoolArray | None:
    return max(regions, key=lambda r: int(r.sum())) if regions else None


def smooth_pixels(z_m: FloatArray, temp_c: FloatArray) -> BoolArray:
    """Pixels with a distance and a temperature whose four neighbours all have both, each
    within an edge step (:data:`EDGE_DEPTH_FRACTION`, :data:`EDGE_TEMP_C`) of the pixel's."""
    z = np.asarray(z_m, np.float64)
    t = np.asarray(temp_c, np.float64)
    smooth = np.isfinite(z) & np.isfinite(t)
    # each pair of neighbours: (previous, next) along the rows, then along the columns
    for prev, nxt in (
        (np.s_[:-1, :], np.s_[1:, :]),
        (np.s_[:, :-1], np.s_[:, 1:]),
    ):
        with np.errstate(invalid="ignore"):  # NaN compares False: not a smooth step
            ok = (
                np.abs(z[nxt] - z[prev])
                <= EDGE_DEPTH_FRACTION * np.fmin(z[nxt], z[prev]) + EDGE_DEPTH_M
            ) & (np.abs(t[nxt] - t[prev]) <= EDGE_TEMP_C)
        smooth[prev] &= ok
        smooth[nxt] &= ok
    return smooth


def find_plate(z_m: FloatArray, temp_c: FloatArray, reference_temp_c: float) -> BoolArray | None:
    """The reference plate: of the regions that are flat in depth and uniform in temperature
    (:func:`smooth_pixels`, 4-connected), those of at least :data:`MIN_TARGET_PX` pixels
    whose mean apparent temperature is within :data:`NEAR_REFERENCE_C` of
    ``reference_temp_c``, the largest; eroded by one pixel (its border may still mix in its
    surroundings through the optics' blur or the registration). None when there is none.

    z_m, temp_c: (h, w) Z (metres) and apparent temperature (C) per thermal pixel."""
    kernel = np.ones((3, 3), np.uint8)
    candidates = []
    for region in _components(smooth_pixels(z_m, temp_c)):
        inner = cv2.erode(region.astype(np.uint8), kernel).astype(bool)
        if inner.sum() < MIN_TARGET_PX:
            continue
        if abs(float(np.mean(temp_c[inner])) - reference_temp_c) <= NEAR_REFERENCE_C:
            candidates.append(inner)
    return _largest(candidates)


def overlap(a: BoolArray, b: BoolArray) -> float:
    """Intersection over union of two masks (0 when both are empty)."""
    union = int(np.count_nonzero(a | b))
    return int(np.count_nonzero(a & b)) / union if union else 0.0
