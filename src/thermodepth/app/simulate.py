"""``thermodepth simulate``: the paper's sweep, frame pairs with ground truth, and board
captures, on the simulated rig."""

from __future__ import annotations

from pathlib import Path

from ..board import BoardSpec
from ..errors import FieldError, check_count
from ..progress import SILENT, Reporter
from ..sim.protocols import (
    SCENES,
    SweepConfig,
    TargetCaptures,
    aggregate_by_vox,
    simulate_sweep,
    simulate_targets,
    write_frames,
)
from ..sweep import SweepTable, write_sweep_csv


def sweep(
    config: SweepConfig, out: Path, by_vox: bool = False, reporter: Reporter = SILENT
) -> SweepTable:
    """Simulate the paper's protocol into the sweep CSV ``out`` (averaged per 1 C of VOx with
    ``by_vox``, as Tables 1-5); the config is checked first (FieldError)."""
    check_count("samples", config.samples)
    if not config.vox_min_c < config.vox_max_c:
        raise FieldError("vox_min_c", "must be below vox_max_c")
    if min(config.distances_m) <= 0:
        raise FieldError("distances_m", "must be positive")
    total = len(config.distances_m) * len(config.plate_temps_c)
    with reporter.task("sweep", total) as advance:
        table = simulate_sweep(config, progress=advance)
    table = aggregate_by_vox(table) if by_vox else table
    write_sweep_csv(out, table)
    return table


def frames(
    out: Path,
    scene: str = "inspection",
    distance_m: float = 1.0,
    count: int = 5,
    seed: int = 0,
    reporter: Reporter = SILENT,
) -> list[Path]:
    """Frame pairs with ground truth (npz per frame) and the rig's calibration in ``out``."""
    if scene not in SCENES:
        raise FieldError("scene", f"unknown {scene!r}; choose from {sorted(SCENES)}")
    check_count("frames", count)
    with reporter.task("frames", count) as advance:
        return write_frames(out, SCENES[scene](), distance_m, count, seed, advance)


def targets(
    out: Path,
    board: str = "checkerboard:9x6",
    square_m: float = 0.03,
    poses: int = 20,
    seed: int = 0,
    reporter: Reporter = SILENT,
) -> TargetCaptures:
    """Heated-board captures (IR + thermal per pose) for ``thermodepth calibrate``."""
    spec = BoardSpec.parse(board, square_m)
    check_count("poses", poses)
    with reporter.task("targets", poses) as advance:
        return simulate_targets(out, spec, poses, seed, progress=advance)
