"""Regions of the depth grid whose sampled values are summed while they are sampled.

A measurement over a region of the fused image (an ROI's mean, extremes, SD and flags)
needs the sampled values, the raw depth and the thermal pixel of each of its pixels, which
:meth:`~thermodepth.registration.Registration.thermal_to_depth` has in cache row by row. It
sums each region there (:func:`~.kernels.sum_row`), so a region costs a few operations per
pixel and no pass over memory of its own. The sums are integers (values in units of 2^-12,
:data:`~.kernels.FIXED_POINT`): exact, whatever the order of the pixels, so they equal those
of numpy over a whole-image mask (``thermodepth.measure.roi_stats``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .base import RowSums
from .kernels import FIXED_POINT


@dataclass(frozen=True, eq=False)
class Region:
    """Where a region's pixels are on the depth grid: the rows and columns of its box, a
    uint8 mask of the box (a single row: the same for every row) and the raw depth values
    its members may have (inclusive; a depth range's)."""

    rows: slice
    cols: slice
    mask: NDArray[np.uint8]
    depth_units: tuple[int, int] = (0, 65535)

    def __post_init__(self) -> None:
        width = max(self.cols.stop - self.cols.start, 0)
        height = max(self.rows.stop - self.rows.start, 0)
        if self.mask.dtype != np.uint8 or self.mask.shape not in ((1, width), (height, width)):
            raise ValueError(
                f"a region's mask must be uint8 (1, {width}) or ({height}, {width}), "
                f"got {self.mask.dtype} {self.mask.shape}"
            )


@dataclass(frozen=True)
class Moments:
    """Exact sums over a region's members with a value: n, the sums of q and of q^2 (ints;
    q: the value in units of 2^-12, :data:`~.kernels.FIXED_POINT`), the least and greatest
    value (NaN when n = 0) and the OR of the flags of the thermal pixels they see."""

    n: int
    sum_q: int
    sum_q2: int
    min: float
    max: float
    flags: int

    @classmethod
    def none(cls, flags: int) -> Moments:
        """The moments of a region without a member that has a value (its flags may still
        say why)."""
        return cls(0, 0, 0, float("nan"), float("nan"), flags)

    @property
    def mean(self) -> float:
        """The mean value (NaN when n = 0)."""
        return self.sum_q / self.n / FIXED_POINT if self.n else float("nan")

    @property
    def sd(self) -> float:
        """The SD of the population (as numpy's std; NaN when n = 0), from exact integers:
        n^2 times the variance is n sum q^2 - (sum q)^2."""
        if not self.n:
            return float("nan")
        spread = self.n * self.sum_q2 - self.sum_q * self.sum_q
        return float(np.sqrt(spread / (self.n * self.n))) / FIXED_POINT


def exact_sum(values: NDArray[np.int64], axis: int | None = None) -> Any:
    """The exact sum of int64 values (up to 2^31 of them; their total may not fit int64):
    the high and low 32 bits summed apart. ``axis``: as numpy's; an int, or a list of ints
    along the other axis."""
    high = (values >> 32).sum(axis=axis).tolist()
    low = (values & 0xFFFFFFFF).sum(axis=axis).tolist()
    if axis is None:
        return (high << 32) + low
    return [(h << 32) + lo for h, lo in zip(high, low, strict=True)]


class Regions:
    """Regions packed once for the kernels; :meth:`row_sums` gives each frame the
    :class:`~.base.RowSums` to fill, :meth:`moments` their totals.

    regions: :class:`Region` s on a depth grid of ``height`` rows.
    """

    def __init__(self, regions: Sequence[Region], height: int) -> None:
        self.count = len(regions)
        self.height = height
        boxes = [(r.rows.start, r.rows.stop, r.cols.start, r.cols.stop) for r in regions]
        self._boxes = np.array(boxes, np.int64).reshape(-1, 4)
        self._units = np.array([r.depth_units for r in regions], np.uint16).reshape(-1, 2)
        starts = np.cumsum([0] + [r.mask.size for r in regions])
        self._masks = np.concatenate([r.mask.ravel() for r in regions] + [np.zeros(0, np.uint8)])
        strides = [r.mask.shape[1] if r.mask.shape[0] > 1 else 0 for r in regions]
        at = list(zip(starts[:-1], strides, strict=True))
        self._mask_at = np.array(at, np.int64).reshape(-1, 2)

    def row_sums(self, flags: NDArray[np.uint8] | None = None) -> RowSums:
        """Fresh sums for one frame; ``flags`` (h, w) uint8 of the thermal pixels (None or
        all zero: none gathered)."""
        gather = np.zeros(0, np.int32)
        if flags is not None and flags.any():
            gather = flags.astype(np.int32).ravel()
        return RowSums(
            self._boxes,
            self._units,
            self._masks,
            self._mask_at,
            gather,
            np.empty((self.count, 4, self.height), np.int64),
            np.empty((self.count, 2, self.height), np.int32),
        )

    @staticmethod
    def moments(rs: RowSums) -> list[Moments]:
        """Each region's totals over its rows, in order."""
        sums, keys = rs.sums, rs.keys
        totals = sums[:, :2].sum(axis=2).tolist()  # n, sum q: far from int64's limits
        squares = exact_sum(sums[:, 2], axis=1)
        flags = np.bitwise_or.reduce(sums[:, 3], axis=1).tolist()
        low = _key_flip(keys[:, 0].min(axis=1)).view(np.float32).tolist()
        high = _key_flip(keys[:, 1].max(axis=1)).view(np.float32).tolist()
        return [
            Moments(n, sum_q, int(sq), lo, hi, fl) if n else Moments.none(fl)
            for (n, sum_q), sq, lo, hi, fl in zip(totals, squares, low, high, flags, strict=True)
        ]


def _key_flip(keys: NDArray[np.int32]) -> NDArray[np.int32]:
    """float32 bits <-> integer keys in the floats' order (the map is its own inverse)."""
    keys = np.asarray(keys, np.int32)
    return keys ^ ((keys >> 31) & np.int32(0x7FFFFFFF))


__all__ = ["Moments", "Region", "Regions", "RowSums", "exact_sum"]
