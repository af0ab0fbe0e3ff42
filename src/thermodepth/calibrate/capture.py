"""Guided capture of board pairs from the rig (``capture-board``): which pairs of a stream are
worth keeping for calibration.

A pair is kept when both cameras see the whole board (a board of exactly the size given),
the board held still (the cameras do not expose at the same instant, so a board in motion is
in two places in one pair), the shutter was open, and its pose adds something: a region of
the thermal image no kept pair covered, or a tilt no kept pair had. Each kept pair is written
as ``captureNNN_ir.png`` (8-bit IR) and ``captureNNN_thermal.npy`` (raw counts), the names
``calibrate`` pairs.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from ..board import BoardSpec
from ..camera import Intrinsics
from .fit import coverage_grid
from .run import detect_view

FloatArray = NDArray[np.float64]

STILL_THERMAL_PX = 0.3
"""How far (thermal px) any corner may move between two pairs for the board to count as
held still: a tenth of a ~3 px square's blur at 1 m, well above the corners' ~0.05 px
noise (docs/calibration.md)."""
STILL_IR_PX = 1.5
"""The same for the IR image (1280x720: ~8x the thermal camera's pixels per degree)."""
NEW_TILT_DEG = 8.0
"""A kept pose whose board normal differs by at least this from every kept one adds a tilt."""

_NAME = re.compile(r"capture(\d+)_(ir\.png|thermal\.npy)")


@dataclass(frozen=True)
class Verdict:
    """What became of one pair: ``kept``, and why not (``"shutter closed"``, ``"no board in
    the thermal image"``, ``"no board in the IR image"``, ``"larger board"``, ``"moving"``,
    ``"adds nothing new"``) or what it added (``"new coverage"``, ``"new tilt"``)."""

    kept: bool
    reason: str


@dataclass(frozen=True)
class _View:
    ir_px: FloatArray
    thermal_px: FloatArray


def tilt_normal(points_px: FloatArray, board: BoardSpec, intr: Intrinsics) -> FloatArray:
    """The board's unit normal in a camera's frame, from its detected points (solvePnP)."""
    ok, rvec, _ = cv2.solvePnP(
        board.object_points_m(), points_px.astype(np.float64), intr.matrix, intr.distortion.copy()
    )
    if not ok:  # pragma: no cover - solvePnP fails only on degenerate input
        return np.array([0.0, 0.0, 1.0])
    return np.asarray(cv2.Rodrigues(rvec)[0][:, 2], dtype=np.float64)


@dataclass
class BoardCapture:
    """Decides, pair by pair, which to keep (see the module docstring) and writes them.

    board: the board; out_dir: where pairs go (numbering continues after those already
    there); ir_intrinsics: the depth camera's (for the board's tilt; a nominal pinhole of
    the IR image's size when None); thermal_shape: (h, w), for coverage.
    """

    board: BoardSpec
    out_dir: Path
    ir_intrinsics: Intrinsics | None = None
    still_thermal_px: float = STILL_THERMAL_PX
    still_ir_px: float = STILL_IR_PX
    new_tilt_deg: float = NEW_TILT_DEG
    kept: list[Path] = field(default_factory=list)
    verdicts: dict[str, int] = field(default_factory=dict)
    _previous: _View | None = None
    _covered: NDArray[np.bool_] | None = None
    _normals: list[FloatArray] = field(default_factory=list)
    _next: int = 0

    def __post_init__(self) -> None:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        taken = [int(m.group(1)) for p in self.out_dir.iterdir() if (m := _NAME.fullmatch(p.name))]
        self._next = max(taken, default=-1) + 1

    @property
    def coverage(self) -> float:
        """The share of the thermal image's cells (8 x 6) the kept pairs' corners cover."""
        return float(self._covered.mean()) if self._covered is not None else 0.0

    def offer(self, ir: NDArray[np.uint8], counts: NDArray[np.uint16], in_ffc: bool) -> Verdict:
        """Judge one pair (IR image, raw thermal counts, the shutter's state); write it when
        it is kept."""
        verdict = self._judge(ir, counts, in_ffc)
        self.verdicts[verdict.reason] = self.verdicts.get(verdict.reason, 0) + 1
        return verdict

    def _judge(self, ir: NDArray[np.uint8], counts: NDArray[np.uint16], in_ffc: bool) -> Verdict:
        if in_ffc:
            self._previous = None
            return Verdict(False, "shutter closed")
        thermal, thermal_edges = detect_view(counts, self.board, True, "homography")
        if thermal is None:  # cheap first: most frames of a session show no board
            self._previous = None
            return Verdict(False, "no board in the thermal image")
        depth, depth_edges = detect_view(ir, self.board, False, "cornersubpix", quick=True)
        if depth is None:
            self._previous = None
            return Verdict(False, "no board in the IR image")
        if thermal_edges or depth_edges:
            self._previous = None
            return Verdict(False, "larger board")
        view = _View(depth.points_px, thermal.points_px)
        previous, self._previous = self._previous, view
        if previous is None or not self._still(previous, view):
            return Verdict(False, "moving")
        h, w = counts.shape
        cells = coverage_grid(view.thermal_px, w, h) > 0
        new_cells = cells if self._covered is None else cells & ~self._covered
        intr = self.ir_intrinsics or _nominal(ir.shape)
        normal = tilt_normal(view.ir_px, self.board, intr)
        angles = [np.degrees(np.arccos(np.clip(abs(normal @ n), 0, 1))) for n in self._normals]
        if new_cells.any():
            reason = "new coverage"
        elif min(angles, default=180.0) >= self.new_tilt_deg:
            reason = "new tilt"
        else:
            return Verdict(False, "adds nothing new")
        self._covered = cells if self._covered is None else self._covered | cells
        self._normals.append(normal)
        self._write(ir, counts)
        return Verdict(True, reason)

    def _still(self, a: _View, b: _View) -> bool:
        """Whether every corner stayed put between two pairs, in both images."""
        moved_t = np.linalg.norm(a.thermal_px - b.thermal_px, axis=1).max()
        moved_d = np.linalg.norm(a.ir_px - b.ir_px, axis=1).max()
        return bool(moved_t <= self.still_thermal_px and moved_d <= self.still_ir_px)

    def _write(self, ir: NDArray[np.uint8], counts: NDArray[np.uint16]) -> None:
        """The pair, each file written whole under a temporary name, then renamed (a crash
        leaves no half file under a name ``calibrate`` reads)."""
        stem = self.out_dir / f"capture{self._next:03d}"
        thermal, ir_png = Path(f"{stem}_thermal.npy"), Path(f"{stem}_ir.png")
        tmp = self.out_dir / f".{stem.name}.tmp"
        with open(tmp, "wb") as fh:
            np.save(fh, np.asarray(counts, dtype=np.uint16))
        os.replace(tmp, thermal)
        ok, png = cv2.imencode(".png", ir)
        assert ok, "PNG encoding of an 8-bit image does not fail"
        tmp.write_bytes(png.tobytes())
        os.replace(tmp, ir_png)
        self.kept.append(stem)
        self._next += 1


def _nominal(shape: tuple[int, ...]) -> Intrinsics:
    """A pinhole of a ~87 deg horizontal view (a D435's) for an image of ``shape``: tilts
    compare well enough without the camera's own intrinsics."""
    h, w = shape[:2]
    return Intrinsics(
        w,
        h,
        w / 2 / np.tan(np.radians(43.5)),
        w / 2 / np.tan(np.radians(43.5)),
        (w - 1) / 2,
        (h - 1) / 2,
    )
