"""Board detection per board style against plain OpenCV, on the simulated rig's captures.

For each way a board is made (``bare`` metal with the pattern painted, a hot ``plate`` with
tape squares in a hot margin, a cold ``mask`` over a warm plate), each pattern (a 9x6
checkerboard of 3 cm squares, a 4x11 asymmetric circle grid of 1.5 cm steps) and each way
the thermal image is saved (raw counts, or an ironbow PNG as viewer tools save frames), the
captures of ``simulate targets`` are searched two ways:

- plain OpenCV, as its samples call it: the image as a user loads it in 8-bit grey (a
  palette image's luminance, raw counts stretched from min to max), both polarities,
  ``findChessboardCorners`` then ``findChessboardCornersSB`` (``findCirclesGrid``,
  asymmetric, for circles);
- ours: ``load_image`` (palettes inverted) and ``detect_board``, then the larger-board check.

The peer of each row is plain OpenCV's count; "missed" counts the images where plain OpenCV
finds the board and we do not (the target is none).
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import cv2
import numpy as np
from rich.table import Table

from thermodepth.board import BoardSpec
from thermodepth.calibrate import detect_board, grid_continues, load_image
from thermodepth.palettes import apply_palette
from thermodepth.sim.protocols import simulate_targets

from .common import OUT, console

POSES = 20
BOARDS = {
    "checkerboard": BoardSpec("checkerboard", 9, 6, 0.03),
    "circles": BoardSpec("circles", 4, 11, 0.015),
}


def plain_grey(path: Path) -> np.ndarray:
    """The 8-bit grey image a user would hand OpenCV."""
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw.ndim == 3:
        return cv2.cvtColor(raw, cv2.COLOR_BGR2GRAY)
    if raw.dtype == np.uint8:
        return raw
    f = raw.astype(np.float64)
    return np.clip((f - f.min()) * 255.0 / max(np.ptp(f), 1.0), 0, 255).astype(np.uint8)


def plain_finds(grey: np.ndarray, board: BoardSpec) -> bool:
    """Whether OpenCV, called as its samples call it, finds the whole board."""
    for img in (grey, 255 - grey):
        if board.kind == "circles":
            found, _ = cv2.findCirclesGrid(
                img, board.pattern_size, flags=cv2.CALIB_CB_ASYMMETRIC_GRID
            )
            if found:
                return True
            continue
        if cv2.findChessboardCorners(img, board.pattern_size)[0]:
            return True
        if cv2.findChessboardCornersSB(img, board.pattern_size)[0]:
            return True
    return False


def ours_finds(path: Path, board: BoardSpec, thermal: bool) -> tuple[bool, bool]:
    """(found, refused as a larger board) for our detection of ``board`` in ``path``."""
    img = load_image(path, thermal)
    det = detect_board(img, board, stretch=True if thermal else None)
    if det is None:
        return False, False
    larger = board.kind == "checkerboard" and bool(grid_continues(img, det.points_px, board))
    return not larger, larger


def ironbow_copy(counts_png: Path) -> Path:
    """The same capture saved as a viewer does: 8-bit RGB in the ironbow palette."""
    counts = cv2.imread(str(counts_png), cv2.IMREAD_UNCHANGED)
    out = counts_png.with_name(counts_png.stem + "_ironbow.png")
    cv2.imwrite(str(out), apply_palette(counts, "ironbow")[..., ::-1])
    return out


def count(paths: list[Path], board: BoardSpec, thermal: bool) -> dict[str, int]:
    """Images, plain OpenCV's finds, ours, ours missed where plain finds, larger refused."""
    plain = ours = missed = larger = 0
    for path in paths:
        p = plain_finds(plain_grey(path), board)
        o, refused = ours_finds(path, board, thermal)
        plain, ours, larger = plain + p, ours + o, larger + refused
        missed += p and not o
    return {"images": len(paths), "plain": plain, "ours": ours, "missed": missed, "larger": larger}


def main() -> None:
    rows = []
    for pattern, board in BOARDS.items():
        for style in ("bare", "plate", "mask"):
            with tempfile.TemporaryDirectory() as tmp:
                caps = simulate_targets(Path(tmp), board, POSES, seed=11, style=style)
                thermal = [t for _, t in caps.pairs]
                for camera, saved, paths in (
                    ("thermal", "counts", thermal),
                    ("thermal", "ironbow", [ironbow_copy(t) for t in thermal]),
                    ("IR", "grey", [ir for ir, _ in caps.pairs]),
                ):
                    found = count(paths, board, camera == "thermal")
                    rows.append(
                        {
                            "pattern": pattern,
                            "style": style,
                            "camera": camera,
                            "saved": saved,
                            **found,
                        }
                    )
    table = Table(title=f"board detection, {POSES} simulated poses per style (seed 11)")
    for col in rows[0]:
        table.add_column(col, justify="left" if isinstance(rows[0][col], str) else "right")
    for r in rows:
        table.add_row(*(str(v) for v in r.values()))
    console.print(table)
    total = sum(r["missed"] for r in rows)
    console.print(
        "  plain: OpenCV as its samples call it; missed: images where plain OpenCV finds the "
        "board and we do not"
    )
    console.print(f"  missed in all: {total} (target: 0)")
    OUT.mkdir(exist_ok=True)
    (OUT / "board_detection.json").write_text(json.dumps(rows, indent=2))
