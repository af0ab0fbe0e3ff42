"""Calibration boards: the targets both cameras see, in OpenCV's terms (the pattern, its size
and the spacing of its points in metres)."""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from .errors import FieldError


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
            raise FieldError(
                "board", f"expected checkerboard:COLSxROWS or circles:COLSxROWS, got {text!r}"
            )
        kind, cols, rows = m.group(1), int(m.group(2)), int(m.group(3))
        if cols < 2 or rows < 2:
            raise FieldError("board", f"need at least 2x2, got {cols}x{rows}")
        if not 0 < spacing_m < math.inf:
            raise FieldError("square_m", f"must be a finite length > 0, got {spacing_m}")
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
