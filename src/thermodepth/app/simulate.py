"""``thermodepth simulate``: the paper's sweep, frame pairs with ground truth, board
captures and sessions, the paper's protocol and walks round a scene, on the simulated rig."""

from __future__ import annotations

from pathlib import Path

from ..board import BoardSpec
from ..errors import FieldError, check_count
from ..io.recording import check_output
from ..palettes import PALETTES
from ..progress import SILENT, Reporter
from ..sim.cameras import depth_mode, thermal_camera
from ..sim.protocols import (
    SCENES,
    ProtocolConfig,
    SweepConfig,
    TargetCaptures,
    aggregate_by_vox,
    session_frames,
    simulate_board_session,
    simulate_protocol,
    simulate_sweep,
    simulate_targets,
    write_frames,
)
from ..sim.scene import BOARD_STYLES
from ..sim.walkaround import WALK_SITES, WalkConfig, simulate_walkaround, walkaround_steps
from ..sweep import SweepTable, write_sweep_csv


def sweep(
    config: SweepConfig, out: Path, by_vox: bool = False, reporter: Reporter = SILENT
) -> SweepTable:
    """Simulate the paper's protocol into the sweep CSV ``out`` (averaged per 1 C of VOx with
    ``by_vox``, as Tables 1-5); the config is checked first (FieldError)."""
    check_count("samples", config.samples)
    _check_vox_range(config)
    check_cameras(config.thermal_camera, None)
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
    camera: str | None = None,
    depth: str | None = None,
) -> list[Path]:
    """Frame pairs with ground truth (npz per frame) and the rig's calibration in ``out``, of
    the simulated cameras ``camera`` and ``depth`` (None: the Lepton 3, 1280x720)."""
    if scene not in SCENES:
        raise FieldError("scene", f"unknown {scene!r}; choose from {sorted(SCENES)}")
    check_count("frames", count)
    check_cameras(camera, depth)
    with reporter.task("frames", count) as advance:
        return write_frames(
            out, SCENES[scene](), distance_m, count, seed, advance, camera=camera, depth=depth
        )


def board_session(
    out: Path,
    board: str = "checkerboard:9x6",
    square_m: float = 0.03,
    poses: int = 12,
    seed: int = 0,
    style: str = "bare",
    hold_s: float = 0.7,
    move_s: float = 0.35,
    reporter: Reporter = SILENT,
    camera: str | None = None,
    depth: str | None = None,
) -> Path:
    """A recording of a board shown to the rig, for ``capture-board``
    (:func:`~thermodepth.sim.protocols.simulate_board_session`), of the simulated cameras
    ``camera`` and ``depth`` (None: the Lepton 3, 1280x720)."""
    spec = BoardSpec.parse(board, square_m)
    check_count("poses", poses)
    _check_style(style)
    _check_seconds(hold_s=hold_s, move_s=move_s)
    check_cameras(camera, depth)
    fps = thermal_camera(camera).sensor.fps
    check_output(out)
    frames = session_frames(poses, hold_s, move_s, fps)
    with reporter.task("board session", frames) as advance:
        return simulate_board_session(
            out, spec, poses, seed, style, hold_s, move_s, progress=advance, camera=camera,
            depth=depth,
        )  # fmt: skip


def walkaround(
    out: Path,
    scene: str = "machine",
    duration_s: float | None = None,
    seed: int = 0,
    reporter: Reporter = SILENT,
    camera: str | None = None,
    depth: str | None = None,
) -> Path:
    """A recording of a walk round a scene with the rig in hand, with its truth, for
    ``thermodepth map`` (:func:`~thermodepth.sim.walkaround.simulate_walkaround`), of the
    simulated cameras ``camera`` and ``depth`` (None: the Lepton 3, 1280x720)."""
    if scene not in WALK_SITES:
        raise FieldError("scene", f"unknown {scene!r}; choose from {', '.join(WALK_SITES)}")
    if duration_s is not None:
        _check_seconds(duration_s=duration_s)
    check_cameras(camera, depth)
    check_output(out)
    config = WalkConfig.of(scene, duration_s, seed, camera, depth)
    with reporter.task(f"walk round the {scene}", walkaround_steps(config)) as advance:
        return simulate_walkaround(out, progress=advance, config=config)


def protocol(out: Path, config: ProtocolConfig, reporter: Reporter = SILENT) -> Path:
    """A recording of the paper's session on the simulated rig, for ``collect-sweep``
    (:func:`~thermodepth.sim.protocols.simulate_protocol`); the config is checked first."""
    if not config.distances_m or min(config.distances_m) <= 0:
        raise FieldError("distances_m", "give one or more distances > 0")
    check_count("pairs_per_distance", config.pairs_per_distance)
    _check_vox_range(config)
    _check_seconds(interval_s=config.interval_s, move_s=config.move_s)
    check_cameras(config.thermal_camera, config.depth_mode)
    check_output(out)
    with reporter.task("protocol", config.pairs) as advance:
        return simulate_protocol(out, config, advance)


def check_cameras(camera: str | None, depth: str | None) -> None:
    """A FieldError for a thermal camera or a depth mode the simulator does not have."""
    thermal_camera(camera)
    depth_mode(depth)


def _check_vox_range(config: SweepConfig | ProtocolConfig) -> None:
    if not config.vox_min_c < config.vox_max_c:
        raise FieldError("vox_min_c", "must be below vox_max_c")


def _check_seconds(**durations_s: float) -> None:
    for name, value in durations_s.items():
        if not value > 0:
            raise FieldError(name, "must be > 0 seconds")


def _check_style(style: str) -> None:
    if style not in BOARD_STYLES:
        raise FieldError("style", f"unknown {style!r}; choose from {', '.join(BOARD_STYLES)}")


def targets(
    out: Path,
    board: str = "checkerboard:9x6",
    square_m: float = 0.03,
    poses: int = 20,
    seed: int = 0,
    reporter: Reporter = SILENT,
    style: str = "bare",
    thermal_format: str = "counts",
    camera: str | None = None,
    depth: str | None = None,
) -> TargetCaptures:
    """Heated-board captures (IR + thermal per pose) for ``thermodepth calibrate``: a board
    of ``style`` (:data:`~thermodepth.sim.scene.BOARD_STYLES`), thermal images saved as the
    camera's raw values or in a palette (``thermal_format``), of the simulated cameras
    ``camera`` and ``depth`` (None: the Lepton 3, 1280x720)."""
    spec = BoardSpec.parse(board, square_m)
    check_count("poses", poses)
    _check_style(style)
    if thermal_format != "counts" and thermal_format not in PALETTES:
        raise FieldError(
            "thermal_format", f"unknown {thermal_format!r}; choose counts or {', '.join(PALETTES)}"
        )
    check_cameras(camera, depth)
    with reporter.task("targets", poses) as advance:
        return simulate_targets(
            out,
            spec,
            poses,
            seed,
            progress=advance,
            style=style,
            thermal_format=thermal_format,
            camera=camera,
            depth=depth,
        )
