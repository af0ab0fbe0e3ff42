"""What every registration method gives: results on both grids, why a depth pixel has no
thermal value, and the protocol the methods implement."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import ClassVar, NamedTuple, Protocol

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration

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


class RowSums(NamedTuple):
    """R regions of the depth grid and, per depth row, the exact sums of the valid sampled
    values in each (filled by :func:`~.kernels.sum_row`).

    ``boxes`` (R, 4) int64: rows v0 <= v < v1, columns u0 <= u < u1; ``units`` (R, 2)
    uint16: the raw depth values a member may have, inclusive; ``masks`` uint8, flat: each
    region's mask of its box at ``mask_at[r, 0]``, rows ``mask_at[r, 1]`` apart (0: one row
    that every row uses); ``flags`` (h * w,) int32: per thermal pixel, OR-ed over the
    pixels each region's members see (size 0: none to gather). Out, per depth row: ``sums``
    (R, 4, H) int64: n, sum q, sum q^2 (q: the value in units of 2^-12, rounded) and the OR
    of the flags; ``keys`` (R, 2, H) int32: the least and greatest value as order-preserving
    keys of their float32 bits."""

    boxes: NDArray[np.int64]
    units: NDArray[np.uint16]
    masks: NDArray[np.uint8]
    mask_at: NDArray[np.int64]
    flags: NDArray[np.int32]
    sums: NDArray[np.int64]
    keys: NDArray[np.int32]


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


@dataclass(frozen=True)
class RegistrationOptions:
    """What the methods may be tuned with: the occlusion test's tolerance (``reproject``), the
    distance the paper's upscale is fitted at (``paper``, metres), and the row chunks a frame
    is split into (``reproject``; None: one per numba thread)."""

    tolerance: OcclusionTolerance = field(default_factory=OcclusionTolerance)
    paper_reference_m: float = 1.5
    chunks: int | None = None


class RegistrationMethod(Protocol):
    """A registration method for one calibration (``REGISTRATION_METHODS``). Inputs arrive
    checked (:class:`~thermodepth.registration.Registration` checks them): depth (H, W)
    uint16, thermal (h, w) float32 C-contiguous, thermal_index None or (H, W) int32, regions
    the :class:`RowSums` to fill (none: zero regions)."""

    name: ClassVar[str]

    def depth_to_thermal(self, depth: NDArray[np.uint16]) -> DepthOnThermal:
        """The nearest surface of each thermal pixel (Z in the thermal frame, and range)."""
        ...

    def thermal_to_depth(
        self,
        depth: NDArray[np.uint16],
        thermal: FloatArray,
        interpolation: str,
        nearest: DepthOnThermal | None,
        thermal_index: NDArray[np.int32] | None,
        regions: RowSums,
    ) -> ThermalOnDepth:
        """The thermal value each depth pixel sees, with the reason where none; each
        region's sums of those values, row by row, into ``regions``."""
        ...

    def thermal_pixel_of_depth(
        self, depth: NDArray[np.uint16]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The thermal (u, v) each depth pixel maps to, float64 (H, W) each, NaN where none
        (invalid depth, behind the camera or beyond the lens' valid radius)."""
        ...


def describe(a: object) -> str:
    """An array's dtype and shape (or the type of what is not an array), for messages."""
    return f"{a.dtype} {a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
