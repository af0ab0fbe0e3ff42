"""The calibration file: both cameras' intrinsics and the depth -> thermal rigid transform.

YAML or JSON (chosen by the file extension), validated on load::

    depth:   {width, height, fx, fy, cx, cy, distortion: [k1, k2, p1, p2, k3], depth_scale_m}
    thermal: {width, height, fx, fy, cx, cy, distortion: [k1, k2, p1, p2, k3]}
    thermal_from_depth: {rotation: [[r00, r01, r02], [r10, r11, r12], [r20, r21, r22]],
                         translation_m: [tx, ty, tz]}

Pixels follow OpenCV conventions (pixel centres at integers); ``depth_scale_m`` converts the
depth camera's integer units to metres (0.001 for a D435). ``thermal_from_depth`` maps a point
in the depth camera's frame to the thermal camera's frame: p_t = R p_d + t.

A bad file raises :class:`~thermodepth.errors.InputError` with one line naming the file and
the field, e.g. ``calib.yaml: thermal.fx: Input should be greater than or equal to 1 (got
-150.0)``.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import yaml
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from .camera import Intrinsics, RigidTransform, is_rotation
from .errors import InputError, read_text, repeated
from .radiometry import PlanckConstants

SCHEMA_VERSION: Literal[1] = 1

Finite = Annotated[float, Field(allow_inf_nan=False)]


SHARED_VIEW_M = (0.5, 1.0, 2.0, 5.0)  # distances at which the two cameras must share a view


class StrictSchema(BaseModel):
    """Base of every file and settings schema: unknown keys, NaN and infinities refused."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class PlanckSchema(StrictSchema):
    """A camera's counts calibration S = O + R / (exp(B / T) - F) as written in files
    (:class:`~thermodepth.radiometry.PlanckConstants`)."""

    R: float = Field(gt=0)
    B: float = Field(gt=0)
    F: float
    O: float  # noqa: E741 (the paper's and FLIR's name)

    def constants(self) -> PlanckConstants:
        return PlanckConstants(**self.model_dump())


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
    thermal: CameraSchema
    thermal_from_depth: TransformSchema
    # a file of another version would be read wrongly: refused, as model files are
    schema_version: Literal[1] = SCHEMA_VERSION


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
    """Depth and thermal intrinsics, the depth unit, and ``thermal_from_depth``."""

    depth: Intrinsics
    thermal: Intrinsics
    depth_scale_m: float
    thermal_from_depth: RigidTransform

    def __post_init__(self) -> None:
        t = self.thermal_from_depth
        if (t.to_frame, t.from_frame) != ("thermal", "depth"):
            raise ValueError(f"expected a thermal_from_depth transform, got {t.name}")
        if not (math.isfinite(self.depth_scale_m) and self.depth_scale_m > 0):
            raise ValueError(f"depth_scale_m must be a finite number > 0, got {self.depth_scale_m}")

    @classmethod
    def from_dict(cls, data: Any, source: str = "<calibration>") -> Calibration:
        """Validate a mapping against the schema; errors name ``source`` and the field."""
        try:
            s = CalibrationSchema.model_validate(data)
        except ValidationError as exc:
            raise InputError(f"{source}: {describe_validation_error(exc)}") from None
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
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema_version": SCHEMA_VERSION,
            "depth": {**camera_dict(self.depth), "depth_scale_m": float(self.depth_scale_m)},
            "thermal": camera_dict(self.thermal),
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


def describe_validation_error(exc: ValidationError) -> str:
    """One line for the first error of a pydantic validation: ``field.path: message``."""
    err = exc.errors()[0]
    loc = ".".join(str(p) for p in err["loc"])
    if err["type"] == "missing":
        msg = "missing"
    elif err["type"] == "extra_forbidden":
        msg = "unknown key"
    else:
        msg = err["msg"].removeprefix("Value error, ")
        # a whole mapping (a check across its keys) would print the whole file section
        if "input" in err and err["type"] != "model_type" and not isinstance(err["input"], dict):
            msg += f" (got {err['input']!r})"
    more = len(exc.errors()) - 1
    suffix = f" [and {more} more problem{'s' if more > 1 else ''}]" if more else ""
    return f"{loc}: {msg}{suffix}" if loc else f"{msg}{suffix}"


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object as a dict; a key given twice raises (json keeps the last, silently)."""
    twice = repeated(k for k, _ in pairs)
    if twice:
        raise ValueError(f"key {', '.join(map(repr, twice))} given twice")
    return dict(pairs)


def read_mapping(path: str | Path) -> Any:
    """Parse a YAML or JSON file; unreadable or malformed files raise a one-line InputError."""
    p = Path(path)
    text = read_text(p)
    is_json = p.suffix.lower() == ".json"
    try:
        data = json.loads(text, object_pairs_hook=_unique_keys) if is_json else yaml.safe_load(text)
    except RecursionError:
        raise InputError(f"{p}: nested too deeply to read") from None
    except (ValueError, yaml.YAMLError) as exc:  # JSONDecodeError; an integer of 5000 digits
        first = str(exc).strip().splitlines()[0]
        raise InputError(f"{p}: not valid {'JSON' if is_json else 'YAML'}: {first}") from None
    if not isinstance(data, dict):
        raise InputError(f"{p}: expected a mapping of keys at the top level")
    return data


def _plain(value: Any) -> Any:
    """numpy scalars and arrays, and tuples, as the Python numbers and lists they hold."""
    if isinstance(value, np.ndarray | np.generic):
        return value.tolist()
    if isinstance(value, tuple):
        return list(value)
    raise TypeError(f"cannot write a {type(value).__name__}")


class _Dumper(yaml.SafeDumper):
    """YAML's safe dumper, writing numpy values and tuples as plain numbers and lists."""


for _kind in (np.ndarray, np.generic, tuple):
    _Dumper.add_multi_representer(_kind, lambda dumper, v: dumper.represent_data(_plain(v)))


def write_mapping(path: str | Path, data: dict[str, Any]) -> None:
    """Write a mapping as JSON (a name ending in .json) or YAML; numpy values become plain."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    if p.suffix.lower() == ".json":
        p.write_text(json.dumps(data, indent=2, default=_plain) + "\n", encoding="utf-8")
    else:
        p.write_text(yaml.dump(data, Dumper=_Dumper, sort_keys=False), encoding="utf-8")


@dataclass(frozen=True)
class BoardSpec:
    """A calibration target in OpenCV's terms.

    checkerboard: ``cols`` x ``rows`` inner corners, squares of ``spacing_m``;
    circles: an asymmetric grid of ``cols`` circles per row and ``rows`` rows, circle ``j`` of
    row ``i`` at ((2 j + i % 2) s, i s) with s = ``spacing_m`` (OpenCV's squareSize).
    """

    kind: Literal["checkerboard", "circles"]
    cols: int
    rows: int
    spacing_m: float

    @classmethod
    def parse(cls, text: str, spacing_m: float) -> BoardSpec:
        """Parse ``checkerboard:9x6`` or ``circles:4x11``; bad text raises InputError."""
        m = re.fullmatch(r"(checkerboard|circles):(\d+)x(\d+)", text.strip())
        if not m:
            raise InputError(
                f"--board: expected checkerboard:COLSxROWS or circles:COLSxROWS, got {text!r}"
            )
        kind, cols, rows = m.group(1), int(m.group(2)), int(m.group(3))
        if cols < 2 or rows < 2:
            raise InputError(f"--board: need at least 2x2, got {cols}x{rows}")
        if not 0 < spacing_m < math.inf:
            raise InputError(f"--square-m: must be a finite length > 0, got {spacing_m}")
        return cls(kind, cols, rows, spacing_m)  # type: ignore[arg-type]

    @property
    def pattern_size(self) -> tuple[int, int]:
        return (self.cols, self.rows)

    def object_points_m(self) -> NDArray[np.float64]:
        """Target points (N, 3) in the board frame, in OpenCV's detection order."""
        i, j = np.meshgrid(np.arange(self.rows), np.arange(self.cols), indexing="ij")
        s = self.spacing_m
        if self.kind == "checkerboard":
            x, y = j * s, i * s
        else:
            x, y = (2 * j + i % 2) * s, i * s
        pts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=-1).astype(np.float64)
        return pts - (pts.max(axis=0) + pts.min(axis=0)) / 2  # centred on the board

    def __str__(self) -> str:
        return f"{self.kind}:{self.cols}x{self.rows}"
