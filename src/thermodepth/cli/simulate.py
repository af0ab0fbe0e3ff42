"""``simulate sweep|frames|targets|board-session|protocol|walkaround`` and ``demo``: the
simulated rig."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .base import (
    BARS,
    AmbientTempC,
    Board,
    BoardStyle,
    DepthMode,
    HumidityPct,
    OutDir,
    Seed,
    ThermalCamera,
    app,
    console,
    one_line_errors,
    parse_floats,
)

simulate_app = typer.Typer(
    help="Simulate the rig: a D435 + a thermal camera (a Lepton 3 unless --thermal-camera).",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(simulate_app, name="simulate")


Distances = Annotated[str, typer.Option(help="The plate's distances, m (comma-separated).")]
VoxMin = Annotated[float, typer.Option(help="The VOx (FPA) temperature at the start, C.")]
VoxMax = Annotated[float, typer.Option(help="The VOx temperature warmed up to, C.")]


@simulate_app.command("sweep")
@one_line_errors
def simulate_sweep_cmd(
    out: Annotated[Path, typer.Option("-o", "--out", help="Sweep CSV to write.")],
    distances: Distances = "0.5,1.0,1.5,2.0,2.5",
    plate_temps: Annotated[str, typer.Option(help="Plate temperatures, C.")] = "39",
    samples: Annotated[
        int, typer.Option(help="Readings per distance and plate temperature.")
    ] = 6000,
    vox_min: VoxMin = 25.0,
    vox_max: VoxMax = 40.0,
    ambient_temp_c: AmbientTempC = 25.0,
    humidity_pct: HumidityPct = 50.0,
    by_vox: Annotated[
        bool, typer.Option("--by-vox", help="Average per 1 C of VOx (Tables 1-5).")
    ] = False,
    seed: Seed = 0,
    thermal_camera: ThermalCamera = None,
) -> None:
    """The paper's protocol: plate-centre ROI readings vs distance and VOx temperature."""
    from ..app.simulate import sweep
    from ..sim.protocols import SweepConfig

    config = SweepConfig(
        tuple(parse_floats(distances, "distances_m")),
        tuple(parse_floats(plate_temps, "plate_temps")),
        vox_min,
        vox_max,
        samples,
        ambient_temp_c,
        humidity_pct,
        seed=seed,
        thermal_camera=thermal_camera or "lepton3",
    )
    table = sweep(config, out, by_vox, BARS)
    console.print(f"wrote {len(table)} rows to {out}")


@simulate_app.command("frames")
@one_line_errors
def simulate_frames_cmd(
    out: OutDir,
    scene: Annotated[
        str, typer.Option(help="plate or inspection (plate + 70 C chip).")
    ] = "inspection",
    distance_m: Annotated[float, typer.Option(help="Rig distance to the plate, m.")] = 1.0,
    frames: Annotated[int, typer.Option(help="Number of frame pairs.")] = 5,
    seed: Seed = 0,
    thermal_camera: ThermalCamera = None,
    depth_mode: DepthMode = None,
) -> None:
    """Frame pairs with ground truth (npz per frame) and the rig's calibration."""
    from ..app.simulate import frames as write_frames

    paths = write_frames(out, scene, distance_m, frames, seed, BARS, thermal_camera, depth_mode)
    console.print(f"wrote {len(paths)} frames and calibration.yaml to {out}")


@simulate_app.command("targets")
@one_line_errors
def simulate_targets_cmd(
    out: OutDir,
    board: Board = "checkerboard:9x6",
    square_m: Annotated[float, typer.Option(help="Square size (circle grid step), m.")] = 0.03,
    poses: Annotated[int, typer.Option(help="Number of board poses.")] = 20,
    seed: Seed = 0,
    style: BoardStyle = "bare",
    thermal_format: Annotated[
        str,
        typer.Option(
            help="Thermal images as raw counts (16-bit PNG) or in a viewer's palette (8-bit "
            "RGB): ironbow, inferno, gray, ..."
        ),
    ] = "counts",
    thermal_camera: ThermalCamera = None,
    depth_mode: DepthMode = None,
) -> None:
    """Heated-board captures (IR + thermal per pose) for `thermodepth calibrate`."""
    from ..app.simulate import targets

    caps = targets(
        out, board, square_m, poses, seed, BARS, style, thermal_format, thermal_camera, depth_mode
    )
    console.print(f"wrote {len(caps.pairs)} pairs and {caps.calibration_path.name} to {out}")


@simulate_app.command("board-session")
@one_line_errors
def simulate_board_session_cmd(
    out: Annotated[Path, typer.Option("-o", "--out", help="Recording to create (.zarr).")],
    board: Board = "checkerboard:9x6",
    square_m: Annotated[float, typer.Option(help="Square size (circle grid step), m.")] = 0.03,
    poses: Annotated[int, typer.Option(help="Number of board poses.")] = 12,
    seed: Seed = 0,
    style: BoardStyle = "bare",
    hold_s: Annotated[float, typer.Option(help="Each pose held this long, s.")] = 0.7,
    move_s: Annotated[float, typer.Option(help="Moving to the next pose, s.")] = 0.35,
    thermal_camera: ThermalCamera = None,
    depth_mode: DepthMode = None,
) -> None:
    """A recording of a board shown to the rig (held, moved, held ...), with the IR image,
    for `thermodepth capture-board`."""
    from ..app.simulate import board_session

    path = board_session(
        out, board, square_m, poses, seed, style, hold_s, move_s, BARS, thermal_camera, depth_mode
    )
    console.print(f"wrote {path}")


@simulate_app.command("protocol")
@one_line_errors
def simulate_protocol_cmd(
    out: Annotated[Path, typer.Option("-o", "--out", help="Recording to create (.zarr).")],
    distances: Distances = "0.5,1.0,1.5,2.0,2.5",
    plate_temp_c: Annotated[float, typer.Option(help="The plate's temperature, C.")] = 39.0,
    pairs: Annotated[int, typer.Option(help="Pairs recorded at each distance.")] = 30,
    interval_s: Annotated[float, typer.Option(help="Time between recorded pairs, s.")] = 20.0,
    move_s: Annotated[
        float, typer.Option(help="Time the plate takes to the next distance, s.")
    ] = 60.0,
    vox_min: VoxMin = 25.0,
    vox_max: VoxMax = 40.0,
    ambient_temp_c: AmbientTempC = 25.0,
    humidity_pct: HumidityPct = 50.0,
    seed: Seed = 0,
    thermal_camera: ThermalCamera = None,
    depth_mode: DepthMode = None,
) -> None:
    """A recording of the paper's session: the plate at each distance while the camera warms
    up through its VOx range (FFC frames included), for `thermodepth collect-sweep`."""
    from ..app.simulate import protocol
    from ..sim.protocols import ProtocolConfig

    config = ProtocolConfig(
        tuple(parse_floats(distances, "distances_m")),
        plate_temp_c,
        vox_min,
        vox_max,
        pairs,
        interval_s,
        move_s,
        ambient_temp_c,
        humidity_pct,
        seed,
        thermal_camera or "lepton3",
        depth_mode or "1280x720",
    )
    path = protocol(out, config, BARS)
    console.print(f"wrote {path}: {config.pairs} pairs")


@simulate_app.command("walkaround")
@one_line_errors
def simulate_walkaround_cmd(
    out: Annotated[Path, typer.Option("-o", "--out", help="Recording to create (.zarr).")],
    scene: Annotated[
        str,
        typer.Option(
            help="machine (a motor, hot bearings, pipes and a cabinet with a hot terminal, "
            "walked round) or room (a room with a radiator and a window, seen from inside)."
        ),
    ] = "machine",
    duration_s: Annotated[
        float | None,
        typer.Option(
            "--duration-s",
            "--duration",
            help="The walk's length, s (default: 30 round the machine, 40 round the room; a "
            "shorter walk goes part of the way out and back).",
        ),
    ] = None,
    seed: Seed = 0,
    thermal_camera: ThermalCamera = None,
    depth_mode: DepthMode = None,
) -> None:
    """A recording of a walk round a scene with the rig in hand, for `thermodepth map`:
    every depth frame (30 fps) and thermal frame (FFCs included), the pairs, and the truth
    (scene, mesh, trajectory, hot spots, what each frame saw). The thermal image smears as
    the rig moves; surfaces are directional and mirrors reflect."""
    from ..app.simulate import walkaround

    path = walkaround(out, scene, duration_s, seed, BARS, thermal_camera, depth_mode)
    console.print(f"wrote {path}")


@app.command("demo")
@one_line_errors
def demo_cmd(
    out: Annotated[Path, typer.Option("--out", "-o", help="Directory for the report.")] = Path(
        "demo-out"
    ),
    quick: Annotated[
        bool, typer.Option("--quick", help="Fewer poses, samples and distances (~20 s).")
    ] = False,
) -> None:
    """The whole story on the simulated rig: calibrate, reproduce the paper, generalise,
    inspect, and write report.md / report.html."""
    from ..app.demo import DemoConfig, run_demo

    summary = run_demo(out, DemoConfig(quick=quick), BARS)
    console.print(f"wrote {out / 'report.md'} and {out / 'report.html'}")
    for line in summary.get("findings", []):
        console.print(f"  - {line}", highlight=False)
