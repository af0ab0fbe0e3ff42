"""Depth <-> thermal registration: which thermal pixel sees the surface of each depth pixel.

Two directions, on one calibration (``thermal_from_depth``, both intrinsics):

- :meth:`Registration.depth_to_thermal`: for every thermal pixel, the nearest surface among
  all depth pixels that land in it (a z-buffer): Z along the thermal optical axis and the
  Euclidean range (what the atmosphere model needs).
- :meth:`Registration.thermal_to_depth`: for every depth pixel, the thermal value of the
  pixel that sees it, NaN with a reason where the depth is invalid, the point falls outside
  the thermal image, or a nearer surface hides it from the thermal camera (the z-buffer
  test). librealsense's align has no such test, so hot objects bleed onto what is behind.

Methods (``REGISTRATION_METHODS``, one file each, :class:`~.base.RegistrationMethod`):

- ``"reproject"`` (default, :mod:`.reproject`): every depth pixel projected through the
  thermal lens with its own depth; exact up to the depth noise. Its numba kernels are in
  :mod:`.kernels`.
- ``"paper"`` (:mod:`.paper`): Lin & Yao 2022, sections 2.1-2.2, the undistorted thermal
  image upscaled to the depth grid with nearest neighbour: right at one distance only.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..calibration import Calibration
from .base import (
    DepthOnThermal,
    FloatArray,
    OcclusionTolerance,
    Reason,
    RegistrationMethod,
    RegistrationOptions,
    ThermalOnDepth,
    describe,
)
from .paper import PaperMethod
from .regions import Moments, Region, Regions, RowSums
from .reproject import ReprojectMethod

REGISTRATION_METHODS: dict[str, Callable[[Calibration, RegistrationOptions], RegistrationMethod]]
REGISTRATION_METHODS = {"reproject": ReprojectMethod, "paper": PaperMethod}
"""Registration methods by name; a new one is a class in its own file of this package with
the :class:`~.base.RegistrationMethod` methods, built from a calibration and the options."""

INTERPOLATIONS = ("nearest", "bilinear")


class Registration:
    """Maps between the depth grid (H, W) and the thermal grid (h, w) of one calibration.

    method: a key of ``REGISTRATION_METHODS``: ``"reproject"`` (exact, occlusion-aware;
    default) or ``"paper"`` (the paper's nearest-neighbour upscale, fitted at
    ``paper_reference_m``); chunks: the row chunks a frame is split into (None: one per
    numba thread). It checks every input, then hands it to the method.
    """

    def __init__(
        self,
        calibration: Calibration,
        method: str = "reproject",
        tolerance: OcclusionTolerance | None = None,
        paper_reference_m: float = 1.5,
        chunks: int | None = None,
    ) -> None:
        if method not in REGISTRATION_METHODS:
            raise ValueError(
                f"unknown registration method {method!r}; choose from {list(REGISTRATION_METHODS)}"
            )
        self.calibration = calibration
        self.method = method
        self.options = RegistrationOptions(
            tolerance or OcclusionTolerance(), paper_reference_m, chunks
        )
        self.strategy = REGISTRATION_METHODS[method](calibration, self.options)
        self._no_regions = Regions([], calibration.depth.height).row_sums()

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
                f"units, got {describe(depth)}"
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
                f"(uint16 counts or float), got {describe(thermal)}"
            )
        return np.ascontiguousarray(thermal, dtype=np.float32)

    # -- the two directions ------------------------------------------------------------------

    def depth_to_thermal(self, depth: NDArray[np.uint16]) -> DepthOnThermal:
        """Distance of the nearest surface seen by each thermal pixel.

        depth: (H, W) uint16 in depth units (0 = invalid). Returns float32 (h, w) arrays:
        Z along the thermal optical axis and the range (metres), NaN where no depth pixel
        lands. ``"paper"``: the depth pixel the upscale maps to each thermal pixel's centre
        (Z and range in the depth camera's frame).
        """
        return self.strategy.depth_to_thermal(self._check_depth(depth))

    def thermal_to_depth(
        self,
        depth: NDArray[np.uint16],
        thermal: NDArray[np.generic],
        interpolation: str = "nearest",
        nearest: DepthOnThermal | None = None,
        thermal_index: NDArray[np.int32] | None = None,
        regions: RowSums | None = None,
    ) -> ThermalOnDepth:
        """The thermal value seen at every depth pixel.

        depth: (H, W) uint16 depth units; thermal: (h, w) counts (uint16) or float (e.g.
        temperatures). interpolation: ``"nearest"`` or ``"bilinear"`` (over the neighbours
        that see the same surface). nearest: :meth:`depth_to_thermal` of this same depth
        frame, if already computed: its Z is the z-buffer of the occlusion test, which is
        then not computed again. thermal_index: an int32 (H, W) array to fill with the flat
        index (v * w + u) of the thermal pixel each depth pixel sees (the nearest one), -1
        where ``reason != Reason.OK``, so other thermal-grid data (flags) can follow without
        a second pass. regions: :meth:`Regions.row_sums` of this depth grid, to fill with
        each region's sums of the values, row by row (:meth:`Regions.moments` totals them).
        Returns float32 (H, W) values, NaN where ``reason != Reason.OK`` (invalid depth,
        outside the thermal image, occluded).
        """
        depth = self._check_depth(depth)
        therm = self._check_thermal(thermal)
        if interpolation not in INTERPOLATIONS:
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
                f"got {describe(thermal_index)}"
            )
        if regions is None:
            regions = self._no_regions
        elif regions.sums.shape[1:] != (4, depth.shape[0]):
            raise ValueError(
                f"regions must be the row sums of a depth grid of {depth.shape[0]} rows, "
                f"got sums of shape {regions.sums.shape}"
            )
        return self.strategy.thermal_to_depth(
            depth, therm, interpolation, nearest, thermal_index, regions
        )

    def thermal_pixel_of_depth(
        self, depth: NDArray[np.uint16]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The thermal (u, v) each depth pixel of a frame maps to, float64 (H, W) each, NaN
        where none (invalid depth, behind the camera, beyond the lens' valid radius); for the
        accuracy of a method against ground truth."""
        return self.strategy.thermal_pixel_of_depth(self._check_depth(depth))


__all__ = [
    "INTERPOLATIONS",
    "REGISTRATION_METHODS",
    "DepthOnThermal",
    "Moments",
    "OcclusionTolerance",
    "Reason",
    "Region",
    "Regions",
    "Registration",
    "RegistrationMethod",
    "RegistrationOptions",
    "RowSums",
    "ThermalOnDepth",
]
