"""The calibration file: both cameras' intrinsics and the depth -> thermal rigid transform.

YAML or JSON (chosen by the file extension), validated on load::

    depth:   {width, height, fx, fy, cx, cy, distortion: [k1, k2, p1, p2, k3], depth_scale_m}
    thermal: {width, height, fx, fy, cx, cy, distortion: [k1, k2, p1, p2, k3],
              output: {kind: counts} | {kind: kelvin, scale_k: S, offset_k: O}}
    thermal_from_depth: {rotation: [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]],
                         translation_m: [tx, ty, tz]}

Pixels follow OpenCV conventions (pixel centres at integers); ``depth_scale_m`` converts the
depth camera's integer units to metres (0.001 for a D435). ``thermal_from_depth`` maps a point
in the depth camera's frame to the thermal camera's frame: p_t = R p_d + t. ``thermal.output``
says what the thermal camera's pixel values are (:class:`~thermodepth.radiometry.ThermalOutput`):
raw counts (the default: files written without it mean this; ``bits`` 14 unless given) or the
camera's own temperature, kelvin = value x scale_k + offset_k.

A bad file raises :class:`~thermodepth.errors.InputError` with one line naming the file and
the field, e.g. ``calib.yaml: thermal.fx: Input should be greater than or equal to 1 (got
-150.0)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from .camera import Intrinsics, RigidTransform, is_rotation
from .errors import FieldError, InputError
from .radiometry import RAW_COUNTS, ThermalOutput
from .schema import Finite, StrictSchema, read_mapping, validated, write_mapping

SCHEMA_VERSION: Literal[1] = 1

SHARED_VIEW_M = (0.5, 1.0, 2.0, 5.0)  # distances at which the two cameras must share a view


class CameraSchema(StrictSchema):
    width: int = Field(gt=0, le=100_000)
    height: int = Field(gt=0, le=100_000)
    # focal lengths in pixels: 1 px is a 179 deg view of a 160 px image, 1e6 px a narrow one
    fx: Finite = Field(ge=1, le=1e6)
    fy: Finite = Field(ge=1, le=1e6)
    cx: Finite
    cy: Finite
    distortion: list[Finite] = Field(min_length=5, max_length=5)

    @model_validator(mode="after")
    def _principal_point_inside(self) -> CameraSchema:
        # Pixel centres at integers: the image spans [-0.5, size - 0.5].
        if not -0.5 <= self.cx <= self.width - 0.5:
            raise ValueError(f"cx={self.cx} is outside the image (width {self.width})")
        if not -0.5 <= self.cy <= self.height - 0.5:
            raise ValueError(f"cy={self.cy} is outside the image (height {self.height})")
        return self


class DepthCameraSchema(CameraSchema):
    depth_scale_m: Finite = Field(gt=0)


class OutputSchema(StrictSchema):
    """``thermal.output``: ``{kind: counts}`` (``bits``: the ADC's, 14 unless given) or
    ``{kind: kelvin, scale_k: S, offset_k: O}`` (kelvin = value x S + O)."""

    kind: Literal["counts", "kelvin"] = "counts"
    scale_k: Finite | None = Field(default=None, gt=0)
    offset_k: Finite | None = None
    bits: int | None = Field(default=None, ge=1, le=32)

    @model_validator(mode="after")
    def _keys_of_kind(self) -> OutputSchema:
        if self.kind == "kelvin":
            if self.scale_k is None:
                raise ValueError("a kelvin output needs scale_k (kelvin per value, e.g. 0.01)")
            if self.bits is not None:
                raise ValueError("bits is for counts; a kelvin output has scale_k and offset_k")
        elif self.scale_k is not None or self.offset_k is not None:
            raise ValueError("scale_k and offset_k are for kind: kelvin; counts take only bits")
        return self

    def output(self) -> ThermalOutput:
        if self.kind == "kelvin":
            assert self.scale_k is not None
            return ThermalOutput.kelvin_per(self.scale_k, self.offset_k or 0.0)
        return ThermalOutput(bits=self.bits or 14)


class ThermalCameraSchema(CameraSchema):
    output: OutputSchema = OutputSchema()


class TransformSchema(StrictSchema):
    rotation: list[list[Finite]] = Field(min_length=3, max_length=3)
    translation_m: list[Finite] = Field(min_length=3, max_length=3)

    @model_validator(mode="after")
    def _orthonormal(self) -> TransformSchema:
        if any(len(row) != 3 for row in self.rotation):
            raise ValueError("rotation must be 3 rows of 3 numbers")
        if not is_rotation(self.rotation, tol=1e-6):
            r = np.asarray(self.rotation)
            err = float(np.max(np.abs(r.T @ r - np.eye(3))))
            raise ValueError(
                f"rotation is not orthonormal with det +1 (max |R^T R - I| = {err:.2e}, "
                f"det = {np.linalg.det(r):.6f}; tolerance 1e-6)"
            )
        return self


class CalibrationSchema(StrictSchema):
    depth: DepthCameraSchema
    thermal: ThermalCameraSchema
    thermal_from_depth: TransformSchema
    # a file of another version would be read wrongly: refused, as model files are
    schema_version: Literal[1] = SCHEMA_VERSION


def parse_output(text: str) -> ThermalOutput:
    """``counts`` (14 bits), ``counts:BITS``, or ``kelvin:SCALE[:OFFSET]`` (kelvin = value x
    SCALE + OFFSET) -> :class:`~thermodepth.radiometry.ThermalOutput`; FieldError
    (``thermal_output``) otherwise."""
    kind, _, rest = text.strip().partition(":")
    try:
        numbers = [float(x) for x in rest.split(":")] if rest else []
        if kind == "counts" and len(numbers) <= 1:
            bits = numbers[0] if numbers else 14.0
            if not bits.is_integer():
                raise ValueError
            return ThermalOutput(bits=int(bits))
        if kind == "kelvin" and 1 <= len(numbers) <= 2:
            return ThermalOutput.kelvin_per(*numbers)
    except ValueError:
        pass
    raise FieldError(
        "thermal_output",
        f"{text!r}: expected counts, counts:BITS or kelvin:SCALE[:OFFSET] (e.g. kelvin:0.01)",
    )


def intrinsics_of(cam: CameraSchema) -> Intrinsics:
    """The :class:`Intrinsics` of a validated camera section."""
    return Intrinsics(
        cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, np.asarray(cam.distortion)
    )


def camera_dict(intr: Intrinsics) -> dict[str, Any]:
    """A camera section (plain floats, as the file schema has it) of :class:`Intrinsics`."""
    return {
        "width": intr.width,
        "height": intr.height,
        "fx": float(intr.fx),
        "fy": float(intr.fy),
        "cx": float(intr.cx),
        "cy": float(intr.cy),
        "distortion": [float(k) for k in intr.distortion],
    }


@dataclass(frozen=True, eq=False)
class Calibration:
    """Depth and thermal intrinsics, the depth unit, ``thermal_from_depth`` and what the
    thermal camera's pixel values are (``thermal_output``)."""

    depth: Intrinsics
    thermal: Intrinsics
    depth_scale_m: float
    thermal_from_depth: RigidTransform
    thermal_output: ThermalOutput = RAW_COUNTS

    def __post_init__(self) -> None:
        t = self.thermal_from_depth
        if (t.to_frame, t.from_frame) != ("thermal", "depth"):
            raise ValueError(f"expected a thermal_from_depth transform, got {t.name}")
        if not (math.isfinite(self.depth_scale_m) and self.depth_scale_m > 0):
            raise ValueError(f"depth_scale_m must be a finite number > 0, got {self.depth_scale_m}")

    @classmethod
    def from_dict(cls, data: Any, source: str = "<calibration>") -> Calibration:
        """Validate a mapping against the schema; errors name ``source`` and the field."""
        s = validated(CalibrationSchema, data, source)
        return cls(
            depth=intrinsics_of(s.depth),
            thermal=intrinsics_of(s.thermal),
            depth_scale_m=s.depth.depth_scale_m,
            thermal_from_depth=RigidTransform(
                np.array(s.thermal_from_depth.rotation),
                np.array(s.thermal_from_depth.translation_m),
                "thermal",
                "depth",
            ),
            thermal_output=s.thermal.output.output(),
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema_version": SCHEMA_VERSION,
            "depth": {**camera_dict(self.depth), "depth_scale_m": float(self.depth_scale_m)},
            "thermal": {**camera_dict(self.thermal), "output": self.thermal_output.as_dict()},
            "thermal_from_depth": {
                "rotation": self.thermal_from_depth.rotation.tolist(),
                "translation_m": self.thermal_from_depth.translation_m.tolist(),
            },
        }

    @classmethod
    def load(cls, path: str | Path) -> Calibration:
        """Read and validate a YAML (.yaml/.yml) or JSON (.json) calibration file; one whose
        cameras see nothing in common (:meth:`shared_view`) is refused too."""
        cal = cls.from_dict(read_mapping(path), source=str(path))
        if not any(cal.shared_view.values()):
            raise InputError(
                f"{path}: the thermal camera sees none of the depth image at "
                f"{min(SHARED_VIEW_M):g}-{max(SHARED_VIEW_M):g} m: check thermal_from_depth "
                "(its direction, the translation in metres) and the thermal distortion"
            )
        return cal

    @cached_property
    def shared_view(self) -> dict[float, float]:
        """Fraction of the depth image (a grid of every 16th pixel) whose surface at each
        distance of ``SHARED_VIEW_M`` (Z, metres) lands in the thermal image; computed once
        (``load`` checks it, ``check-calibration`` reports it)."""
        step = 16
        u, v = np.meshgrid(
            np.arange(0, self.depth.width, step, dtype=np.float64),
            np.arange(0, self.depth.height, step, dtype=np.float64),
        )
        pixels = np.stack([u.ravel(), v.ravel()], axis=-1)
        out = {}
        for z in SHARED_VIEW_M:
            points = self.thermal_from_depth.apply(self.depth.deproject(pixels, z))
            with np.errstate(invalid="ignore", over="ignore"):
                inside = self.thermal.contains(self.thermal.project(points))
            out[z] = float(inside.mean())
        return out

    def save(self, path: str | Path) -> None:
        """Write YAML or JSON by extension, floats at full precision (round-trips exactly)."""
        write_mapping(path, self.to_dict())

    @property
    def baseline_m(self) -> float:
        """Distance between the two optical centres, metres."""
        return self.thermal_from_depth.distance_m
