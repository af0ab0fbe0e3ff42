"""The ``thermodepth`` command line: typer signatures and rich printing over the application
layer (:mod:`thermodepth.app`), which does the work.

Each command parses its options, calls one plain function and prints what it returns. Errors
are one red line: a :class:`~thermodepth.errors.FieldError` is shown with the option that
gave the field (``--emissivity: ...``).
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
)
from rich.table import Table

from . import __version__
from .errors import FieldError, ThermodepthError

if TYPE_CHECKING:
    from .calibrate import CalibrationResult
    from .conditions import Conditions
    from .pipeline import FusedFrame
    from .progress import Progress as Advance
    from .session import SessionResult

app = typer.Typer(
    name="thermodepth",
    help="Fuse a depth camera with a radiometric thermal camera: true temperature, in 3D.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # click's plain help: wraps at words, no type column for flags
)
console = Console()
err_console = Console(stderr=True)

F = TypeVar("F", bound=Callable[..., Any])

FLAGS = {
    "max_skew_s": "--max-skew-ms",
    "thermal_latency_s": "--thermal-latency-ms",
    "duration_s": "--duration",
    "out_dir": "--out",
    "preset_name": "--preset",
    "vox_min_c": "--vox-min",
    "distances_m": "--distances",
    "sweep": "SWEEP",
}
"""The option of each field whose flag is not ``--`` + the field with dashes."""


def flag_of(field: str) -> str:
    """The command-line option that gives ``field``."""
    return FLAGS.get(field, "--" + field.replace("_", "-"))


def one_line_errors(func: F) -> F:
    """Print a ThermodepthError as one red line on stderr (a FieldError with its option's
    name) and exit with code 2."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except FieldError as exc:
            _error_line(f"{flag_of(exc.field)}: {exc.message}")
        except ThermodepthError as exc:
            _error_line(str(exc))

    return wrapper  # type: ignore[return-value]


def _error_line(message: str) -> None:
    err_console.print(f"[red]error:[/red] {escape(message)}", highlight=False, soft_wrap=True)
    raise typer.Exit(2)


def warn_line(message: str) -> None:
    """A one-line warning on stderr, brackets printed as they are."""
    err_console.print(
        f"[yellow]warning:[/yellow] {escape(message)}", highlight=False, soft_wrap=True
    )


def print_json(data: Any) -> None:
    """Strict JSON on stdout (NaN and infinities as null, which other parsers refuse)."""
    from .io.measurements import jsonable

    print(json.dumps(jsonable(data), indent=2))


def _version(value: bool) -> None:
    if value:
        console.print(f"thermodepth {__version__}")
        raise typer.Exit()


@app.callback()
def _main(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_version, is_eager=True, help="Print the version."),
    ] = False,
) -> None:
    """thermodepth: depth + thermal fusion for true temperature in 3D."""


# -- progress ---------------------------------------------------------------------------------


class RichReporter:
    """A :class:`~thermodepth.progress.Reporter` drawing rich progress bars on stderr."""

    @contextmanager
    def task(self, description: str, total: int | None) -> Iterator[Advance]:
        with Progress(
            SpinnerColumn(),
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=err_console,
        ) as bar:
            task = bar.add_task(description, total=total)

            def advance(n: int = 1, /, description: str | None = None) -> None:
                bar.update(task, advance=n, description=description)

            yield advance


BARS = RichReporter()


# -- shared options ---------------------------------------------------------------------------

Emissivity = Annotated[float, typer.Option(help="Object emissivity (0, 1].")]
AmbientTempC = Annotated[
    float, typer.Option(help="Air (and reflected surroundings) temperature, C.")
]
ReflectedTempC = Annotated[
    float | None, typer.Option(help="Reflected apparent temperature, C (default: the air's).")
]
HumidityPct = Annotated[float, typer.Option(help="Relative humidity, %.")]
MaxSkewMs = Annotated[float, typer.Option(help="Pairing: drop pairs further apart in time, ms.")]
ThermalLatencyMs = Annotated[
    float,
    typer.Option(
        help="Lepton: subtract this from each frame's arrival time, ms (exposure to arrival; "
        "default 0: not calibrated)."
    ),
]
Board = Annotated[
    str, typer.Option(help="checkerboard:COLSxROWS (inner corners) or circles:COLSxROWS.")
]


def conditions_of(
    emissivity: float, ambient_temp_c: float, humidity_pct: float, reflected: float | None = None
) -> Conditions:
    """The viewing conditions the options give (FieldError names a bad one)."""
    from .conditions import Conditions

    return Conditions(emissivity, ambient_temp_c, reflected, humidity_pct)


def parse_floats(text: str, field: str) -> list[float]:
    """Comma-separated numbers of an option (``0.5,1,1.5``); FieldError names the field."""
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise FieldError(field, f"expected comma-separated numbers, got {text!r}") from None
    if not values:
        raise FieldError(field, "expected at least one number")
    return values


# -- calibration files ------------------------------------------------------------------------


@app.command("check-calibration")
@one_line_errors
def check_calibration_cmd(
    path: Annotated[Path, typer.Argument(help="Calibration file (.yaml, .yml or .json).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Validate a calibration file and summarise it (sizes, baseline, rotation)."""
    from .app.calibrate import check_calibration

    summary = check_calibration(path)
    if as_json:
        print_json(summary)
        return
    table = Table(title=f"{path}: valid", show_header=False)
    for key, value in summary.items():
        table.add_row(key, str(value))
    console.print(table)


@app.command("temperature")
@one_line_errors
def temperature_cmd(
    counts: Annotated[list[float], typer.Argument(help="Raw counts (one or more).")],
    preset: Annotated[str, typer.Option(help="Planck constants preset.")] = "paper2022",
    emissivity: Emissivity = 1.0,
    distance_m: Annotated[float, typer.Option(help="Object distance, metres.")] = 0.0,
    ambient_temp_c: AmbientTempC = 25.0,
    reflected_temp_c: ReflectedTempC = None,
    humidity_pct: HumidityPct = 50.0,
    method: Annotated[str, typer.Option(help="Radiometric model: flir or thermimage.")] = "flir",
) -> None:
    """Convert raw counts to object temperature (C) with emissivity and atmosphere."""
    from .app.temperature import counts_to_celsius

    conditions = conditions_of(emissivity, ambient_temp_c, humidity_pct, reflected_temp_c)
    temps = counts_to_celsius(counts, conditions, distance_m, preset, method)
    for s, t in zip(counts, temps, strict=True):
        if math.isfinite(t):
            console.print(f"{s:g} counts -> {t:.3f} C")
        else:  # raw_to_kelvin's NaN: invalid counts, or no object signal above the offset
            console.print(f"{s:g} counts -> none (invalid, or no signal above the surroundings)")


# -- simulate -------------------------------------------------------------------------------

simulate_app = typer.Typer(
    help="Simulate the D435 + Lepton 3 rig (sweeps, frames, targets).",
    no_args_is_help=True,
    rich_markup_mode=None,
)
app.add_typer(simulate_app, name="simulate")


@simulate_app.command("sweep")
@one_line_errors
def simulate_sweep_cmd(
    out: Annotated[Path, typer.Option("-o", "--out", help="Sweep CSV to write.")],
    distances: Annotated[
        str, typer.Option(help="Distances, m (comma-separated).")
    ] = "0.5,1.0,1.5,2.0,2.5",
    plate_temps: Annotated[str, typer.Option(help="Plate temperatures, C.")] = "39",
    samples: Annotated[
        int, typer.Option(help="Readings per distance and plate temperature.")
    ] = 6000,
    vox_min: Annotated[float, typer.Option(help="Lowest VOx (FPA) temperature, C.")] = 25.0,
    vox_max: Annotated[float, typer.Option(help="Highest VOx (FPA) temperature, C.")] = 40.0,
    ambient_temp_c: AmbientTempC = 25.0,
    humidity_pct: HumidityPct = 50.0,
    by_vox: Annotated[
        bool, typer.Option("--by-vox", help="Average per 1 C of VOx (Tables 1-5).")
    ] = False,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """The paper's protocol: plate-centre ROI readings vs distance and VOx temperature."""
    from .app.simulate import sweep
    from .sim.protocols import SweepConfig

    config = SweepConfig(
        tuple(parse_floats(distances, "distances_m")),
        tuple(parse_floats(plate_temps, "plate_temps")),
        vox_min,
        vox_max,
        samples,
        ambient_temp_c,
        humidity_pct,
        seed=seed,
    )
    table = sweep(config, out, by_vox, BARS)
    console.print(f"wrote {len(table)} rows to {out}")


@simulate_app.command("frames")
@one_line_errors
def simulate_frames_cmd(
    out: Annotated[Path, typer.Option("-o", "--out", help="Directory to write.")],
    scene: Annotated[
        str, typer.Option(help="plate or inspection (plate + 70 C chip).")
    ] = "inspection",
    distance_m: Annotated[float, typer.Option(help="Rig distance to the plate, m.")] = 1.0,
    frames: Annotated[int, typer.Option(help="Number of frame pairs.")] = 5,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """Frame pairs with ground truth (npz per frame) and the rig's calibration."""
    from .app.simulate import frames as write_frames

    paths = write_frames(out, scene, distance_m, frames, seed, BARS)
    console.print(f"wrote {len(paths)} frames and calibration.yaml to {out}")


@simulate_app.command("targets")
@one_line_errors
def simulate_targets_cmd(
    out: Annotated[Path, typer.Option("-o", "--out", help="Directory to write.")],
    board: Board = "checkerboard:9x6",
    square_m: Annotated[float, typer.Option(help="Square size (circle grid step), m.")] = 0.03,
    poses: Annotated[int, typer.Option(help="Number of board poses.")] = 20,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """Heated-board captures (IR + thermal per pose) for `thermodepth calibrate`."""
    from .app.simulate import targets

    caps = targets(out, board, square_m, poses, seed, BARS)
    console.print(f"wrote {len(caps.pairs)} pairs and {caps.calibration_path.name} to {out}")


# -- compensation -----------------------------------------------------------------------------


@app.command("fit-compensation")
@one_line_errors
def fit_compensation_cmd(
    sweep: Annotated[Path | None, typer.Argument(help="Sweep CSV (see README).")] = None,
    out: Annotated[
        Path, typer.Option("-o", "--out", help="Model file to write (.json, .yaml).")
    ] = Path("model.json"),
    method: Annotated[
        str, typer.Option(help="radiance (ours, default), paper, or none (physics only).")
    ] = "radiance",
    preset: Annotated[
        str | None,
        typer.Option(help="Write a published model instead of fitting: paper2022 (eq. 20)."),
    ] = None,
    reference_temp_c: Annotated[
        float | None,
        typer.Option(
            help="paper: the reference temperature (C) to fit at (default 39 if present)."
        ),
    ] = None,
    ambient_temp_c: Annotated[
        float, typer.Option(help="Air temperature (C) for rows without ambient_temp_c.")
    ] = 25.0,
    humidity_pct: Annotated[
        float, typer.Option(help="Relative humidity (%) for rows without humidity_pct.")
    ] = 50.0,
    emissivity: Annotated[
        float, typer.Option(help="Emissivity for rows without emissivity.")
    ] = 0.95,
) -> None:
    """Fit a distance + VOx compensation model on a sweep (or write a published preset)."""
    from .app.compensation import fit_compensation

    conditions = conditions_of(emissivity, ambient_temp_c, humidity_pct)
    fitted = fit_compensation(sweep, out, method, preset, reference_temp_c, conditions)
    console.print(f"wrote {fitted.model.method} model to {out}")
    for line in fitted.notes:
        console.print(f"  {line}", highlight=False)
    for line in fitted.warnings:
        warn_line(line)


@app.command("compensate")
@one_line_errors
def compensate_cmd(
    model: Annotated[Path, typer.Argument(help="Model file (fit-compensation).")],
    readings: Annotated[
        Path,
        typer.Argument(
            help="Readings CSV: distance_m, vox_temp_c, measured_temp_c (+ optional columns)."
        ),
    ],
    out: Annotated[Path, typer.Option("-o", "--out", help="CSV to write.")],
) -> None:
    """Add compensated_temp_c and flag columns to a readings CSV."""
    from .app.compensation import compensate_file

    n, flagged = compensate_file(model, readings, out)
    console.print(f"wrote {n} rows to {out} ({flagged} flagged)")


@app.command("evaluate")
@one_line_errors
def evaluate_cmd(
    model: Annotated[Path, typer.Argument(help="Model file (fit-compensation).")],
    test: Annotated[Path, typer.Argument(help="Test sweep CSV with reference_temp_c.")],
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object on stdout.")] = False,
    by_vox: Annotated[
        bool, typer.Option("--by-vox", help="Also the layout of the paper's Tables 1-5.")
    ] = False,
    plot: Annotated[Path | None, typer.Option(help="Write Figs. 13 and 14 (PNG) here.")] = None,
) -> None:
    """Score a model on a test sweep: the paper's Table 6 metric and RMSE, max |error|, SD."""
    from .app.compensation import evaluate

    report = evaluate(model, test, by_vox, plot)
    if as_json:
        print_json(report)
        return
    print_scores(f"{test}: {report['method']} model", report["per_distance"], report["overall"])
    if set(report["flags"]) != {"ok"}:
        console.print(f"flags: {report['flags']}")
    print_by_vox(report.get("by_vox", []))
    for path in report.get("figures", []):
        console.print(f"wrote {path}")


def print_scores(title: str, rows: list[dict[str, Any]], total: dict[str, Any]) -> None:
    """A table per target and distance: the paper's Table 6 figure and the stricter ones."""
    table = Table(title=title)
    for col in (
        "target C",
        "distance m",
        "n",
        "mean C",
        "error of mean %",
        "RMSE C",
        "max |error| C",
        "SD C",
    ):
        table.add_column(col, justify="right")
    for r in rows:
        table.add_row(
            f"{r['reference_temp_c']:g}",
            f"{r['distance_m']:g}",
            str(r["n"]),
            f"{r['mean_c']:.3f}",
            # no such percentage of a 0 C target
            f"{r['error_of_mean_pct']:.3f}" if math.isfinite(r["error_of_mean_pct"]) else "n/a",
            f"{r['rmse_c']:.3f}",
            f"{r['max_abs_error_c']:.3f}",
            f"{r['sd_c']:.3f}",
        )
    console.print(table)
    console.print(
        f"all {total['n']} readings: RMSE {total['rmse_c']:.3f} C, max |error| "
        f"{total['max_abs_error_c']:.3f} C, mean error {total['mean_error_c']:+.3f} C"
    )


def print_by_vox(blocks: list[dict[str, Any]]) -> None:
    """Tables 1-5 of the paper: per target temperature, the mean compensated reading with a
    row per VOx temperature and a column per distance (fits 80 columns, also when piped)."""
    for temp in dict.fromkeys(b["reference_temp_c"] for b in blocks):
        group = [b["mean_c_by_vox"] for b in blocks if b["reference_temp_c"] == temp]
        table = Table(title=f"{temp:g} C target: mean compensated reading, C (Tables 1-5)")
        table.add_column("VOx C", justify="right")
        for b in blocks:
            if b["reference_temp_c"] == temp:
                table.add_column(f"{b['distance_m']:g} m", justify="right")
        for vox in dict.fromkeys(k for cells in group for k in cells):
            table.add_row(vox, *(f"{c[vox]:.3f}" if vox in c else "" for c in group))
        console.print(table)


@app.command("paper-tables")
@one_line_errors
def paper_tables_cmd(
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object on stdout.")] = False,
) -> None:
    """The paper's Tables 1-5 recomputed into Table 6, with the figures the paper omits."""
    from .app.compensation import paper_tables

    report = paper_tables()
    if as_json:
        print_json(report)
        return
    table = Table(title="Lin & Yao 2022, Table 6: published vs recomputed from Tables 1-5")
    for col in (
        "distance m",
        "published avg C",
        "published error %",
        "recomputed avg C",
        "recomputed error %",
        "max |error| C",
        "SD C",
    ):
        table.add_column(col, justify="right")
    for pub, rec in zip(report["published"], report["recomputed"], strict=True):
        table.add_row(
            f"{pub['distance_m']:g}",
            f"{pub['average_c']:.3f}",
            f"{pub['error_pct']:.3f}",
            f"{rec['mean_c']:.3f}",
            f"{rec['error_of_mean_pct']:.3f}",
            f"{rec['max_abs_error_c']:.3f}",
            f"{rec['sd_c']:.3f}",
        )
    console.print(table)
    o = report["overall"]
    console.print(
        f"what the paper does not show: single readings are off by up to "
        f"{o['max_abs_error_c']:.2f} C (RMSE {o['rmse_c']:.3f} C over {o['n']})"
    )


# -- cameras and recordings -------------------------------------------------------------------


@app.command("devices")
@one_line_errors
def devices_cmd(
    as_json: Annotated[bool, typer.Option("--json", help="Print as JSON.")] = False,
) -> None:
    """List attached RealSense cameras and PureThermal (Lepton) boards."""
    from .app.devices import describe_devices, list_devices

    found = list_devices()
    if as_json:
        print_json(found)
        return
    for line in describe_devices(found):
        console.print(line, highlight=False, soft_wrap=True)


@app.command("record")
@one_line_errors
def record_cmd(
    source: Annotated[
        str,
        typer.Option(
            "--source",
            "-s",
            help="sim, realsense[:SERIAL|:FILE], lepton[:N], realsense+lepton, recording:PATH.",
        ),
    ],
    out: Annotated[Path, typer.Option("-o", "--out", help="Recording to create (.zarr).")],
    duration: Annotated[
        float | None, typer.Option("--duration", help="Stop after so many seconds.")
    ] = None,
    frames: Annotated[
        int | None, typer.Option("--frames", help="Stop after so many pairs (or frames).")
    ] = None,
    calibration: Annotated[
        Path | None,
        typer.Option(
            help="Calibration file (thermal intrinsics, extrinsics) to store; a RealSense's "
            "own depth intrinsics replace its depth section (sim and recordings keep theirs)."
        ),
    ] = None,
    max_skew_ms: MaxSkewMs = 20.0,
    thermal_latency_ms: ThermalLatencyMs = 0.0,
    ir: Annotated[bool, typer.Option("--ir", help="Also record the infrared image.")] = False,
    overwrite: Annotated[
        bool,
        typer.Option("--overwrite", help="Replace an existing recording (nothing else)."),
    ] = False,
) -> None:
    """Record a source into a crash-safe Zarr v3 recording (Ctrl-C stops cleanly)."""
    from .app.record import RecordOptions, record

    options = RecordOptions(
        source,
        out,
        duration,
        frames,
        calibration,
        max_skew_ms / 1000.0,
        thermal_latency_ms / 1000.0,
        ir,
        overwrite,
    )
    result = record(options, BARS, warn_line)
    console.print(
        f"wrote {out}: {result.recorder.summary()}; stopped: {result.stopped}", soft_wrap=True
    )
    print_source_stats(result)
    if result.error:
        raise ThermodepthError(f"{result.error}; the recording keeps every frame up to then")


def print_source_stats(result: SessionResult) -> None:
    """The pairing statistics and the source's counters of a session, one line each."""
    if result.pairing is not None:
        by = f" (paired by {result.pairing_by})" if result.pairing_by else ""
        line = result.pairing.summary() if not result.pairing_by else result.pairing.skew_summary()
        console.print(f"pairing{by}: {line}", soft_wrap=True, highlight=False)
    if result.counters:
        counts = ", ".join(f"{k} {v}" for k, v in result.counters.items())
        console.print(f"source: {counts}", soft_wrap=True, highlight=False)


# -- run ------------------------------------------------------------------------------------


@app.command("run")
@one_line_errors
def run_cmd(
    source: Annotated[
        str,
        typer.Option(
            help="Where frames come from: sim, realsense+lepton, recording:PATH (see README)."
        ),
    ] = "sim",
    settings: Annotated[
        Path | None, typer.Option(help="Settings YAML (calibration, compensation, rules).")
    ] = None,
    record: Annotated[
        Path | None, typer.Option(help="Also record everything to this .zarr.")
    ] = None,
    frames: Annotated[int | None, typer.Option(help="Stop after this many pairs.")] = None,
    out: Annotated[
        Path | None,
        typer.Option(
            "-o", "--out", help="Write measurements.jsonl, alarms.jsonl and hotspots.csv here."
        ),
    ] = None,
    max_skew_ms: MaxSkewMs = 20.0,
    thermal_latency_ms: ThermalLatencyMs = 0.0,
    quiet: Annotated[bool, typer.Option("--quiet", help="No line per frame.")] = False,
) -> None:
    """Fuse a stream, print live measurements and alarms (Ctrl-C stops cleanly)."""
    from .app.run import RunOptions, run
    from .sinks import CallbackSink

    options = RunOptions(
        source, settings, frames, out, record, max_skew_ms / 1000.0, thermal_latency_ms / 1000.0
    )
    result = run(options, [] if quiet else [CallbackSink(print_frame)], warn_line)
    console.print(
        f"{result.frames} frames fused ({result.shutter_frames} while the shutter was "
        f"closed), {sum(e['event'] == 'alarm' for e in result.events)} alarms; "
        f"stopped: {result.stopped}"
    )
    for line in result.outputs:
        console.print(line, soft_wrap=True, highlight=False)
    print_source_stats(result)
    if result.error:
        raise ThermodepthError(result.error)


def _flag_note(flags: int) -> str:
    """`` [vox_outside]``: the compensation flags a reading carries (beyond what the model
    was fitted on: a number to doubt), or nothing when it has none."""
    from .compensation import names_of
    from .pipeline import PixelFlag

    names = names_of(flags, PixelFlag)
    return f" [{', '.join(names)}]" if names else ""


def print_frame(fused: FusedFrame) -> None:
    """One line per fused frame: time, VOx, the hottest hotspot, ROIs, alarms."""
    if fused.in_ffc:
        console.print(
            f"[dim]frame {fused.index:5d}  t={fused.thermal_time_s:8.2f} s  shutter "
            "closed (FFC): not measured[/dim]"
        )
        return
    parts = [
        f"frame {fused.index:5d}  t={fused.thermal_time_s:8.2f} s  VOx {fused.vox_temp_c:5.2f} C"
    ]
    if fused.hotspots:
        h = fused.hotspots[0]
        parts.append(
            f"hottest {h.max_c:6.2f} C at {h.distance_m:.2f} m "
            f"({h.area_m2 * 1e4:.1f} cm2{'' if h.resolvable else ', too small'})"
            + _flag_note(h.flags)
        )
    parts += [f"{r.name} {r.mean_c:.2f} C{_flag_note(r.flags)}" for r in fused.rois if r.n]
    console.print("  ".join(parts), highlight=False, soft_wrap=True, markup=False)
    for e in fused.events:
        style = "bold red" if e["event"] == "alarm" else "green"
        console.print(
            f"[{style}]{e['event'].upper()} {escape(e['rule'])}: {e['value_c']} C "
            f"(above {e['above_c']} C for {e['for_frames']} frames)[/{style}]"
        )


# -- calibrate ------------------------------------------------------------------------------


@app.command("calibrate")
@one_line_errors
def calibrate_cmd(
    pairs_dir: Annotated[
        Path,
        typer.Argument(
            help="Folder of image pairs: <stem>_ir|_color|_rgb + <stem>_thermal, or "
            "left<key> (depth camera) + right<key> (thermal); PNG, TIFF, JPEG or .npy."
        ),
    ],
    square_m: Annotated[
        float, typer.Option("--square-m", help="Square size (circle grid step), metres.")
    ],
    board: Board = "checkerboard:9x6",
    out: Annotated[Path, typer.Option("-o", "--out", help="Calibration file to write.")] = Path(
        "calib.yaml"
    ),
    depth_intrinsics: Annotated[
        Path | None,
        typer.Option(
            help="Hold the depth camera's intrinsics fixed: a calibration file (its depth "
            "section) or a YAML/JSON of width, height, fx, fy, cx, cy, distortion."
        ),
    ] = None,
    depth_scale_m: Annotated[
        float | None,
        typer.Option(help="Depth unit, m (default: from --depth-intrinsics, else 0.001)."),
    ] = None,
    thermal_model: Annotated[
        str, typer.Option(help="Thermal distortion terms: no-k3, radial, full or none.")
    ] = "no-k3",
    depth_model: Annotated[
        str, typer.Option(help="Depth camera distortion terms: radial, no-k3, full or none.")
    ] = "radial",
    thermal_refine: Annotated[
        str,
        typer.Option(
            help="Thermal corner refinement: homography (fronto-parallel) or cornersubpix."
        ),
    ] = "homography",
    drop_outliers: Annotated[
        bool, typer.Option("--drop-outliers", help="Fit again without the outlier images.")
    ] = False,
    report_dir: Annotated[
        Path | None,
        typer.Option(help="Where to write calib_report.json/.png (default: next to --out)."),
    ] = None,
) -> None:
    """Calibrate the depth + thermal pair from board captures: thermal (and depth)
    intrinsics and thermal_from_depth, with a quality report."""
    from .app.calibrate import CalibrateOptions, calibrate

    options = CalibrateOptions(
        pairs_dir,
        square_m,
        board,
        out,
        depth_intrinsics,
        depth_scale_m,
        thermal_model,
        depth_model,
        thermal_refine,
        drop_outliers,
        report_dir,
    )
    outcome = calibrate(options, BARS)
    print_calibration_report(outcome.result)
    console.print(f"wrote {', '.join(map(str, outcome.files))}", highlight=False)


def print_calibration_report(result: CalibrationResult) -> None:
    """The terminal report of a calibration: the fit, per-image errors, skipped files."""
    rep = result.report_dict()
    d, t, st = rep["depth_camera"], rep["thermal_camera"], rep["stereo"]
    summary = Table(title=f"calibration from {rep['pairs_used']} pairs ({rep['board']})")
    summary.add_column("")
    summary.add_column("depth camera", justify="right")
    summary.add_column("thermal camera", justify="right")

    def both(key: str, fmt: str) -> None:
        summary.add_row(key, fmt.format(d[key]), fmt.format(t[key]))

    summary.add_row("size px", "{}x{}".format(*d["size"]), "{}x{}".format(*t["size"]))
    summary.add_row("distortion model", d["model"], t["model"])
    summary.add_row("RMS px", f"{d['rms_px']:.3f}", f"{t['rms_px']:.3f}")
    for key in ("fx", "fy", "cx", "cy"):
        both(key, "{:.2f}")
    summary.add_row(
        "principal point - centre px",
        "{:+.2f}, {:+.2f}".format(*d["principal_point_offset_px"]),
        "{:+.2f}, {:+.2f}".format(*t["principal_point_offset_px"]),
    )
    summary.add_row(
        "distortion k1 k2 p1 p2 k3",
        " ".join(f"{k:.4g}" for k in d["distortion"]),
        " ".join(f"{k:.4g}" for k in t["distortion"]),
    )
    summary.add_row(
        "corner coverage",
        f"{rep['coverage']['depth_fraction']:.0%}",
        f"{rep['coverage']['thermal_fraction']:.0%}",
    )
    summary.add_section()
    summary.add_row("stereo rms px", f"{st['rms_px']:.3f}", "")
    summary.add_row("baseline mm", f"{st['baseline_mm']:.2f}", "")
    summary.add_row("translation mm", ", ".join(f"{v:.2f}" for v in st["translation_mm"]), "")
    summary.add_row("rotation deg", f"{st['rotation_deg']:.3f}", "")
    console.print(summary)

    per = Table(title="RMS reprojection error per image, px")
    for col in ("pair", "depth", "thermal", "stereo depth", "stereo thermal", ""):
        per.add_column(col, justify="left" if col == "pair" else "right")
    for row in rep["per_image"]:
        per.add_row(
            row["name"],
            f"{row['depth_rms_px']:.3f}",
            f"{row['thermal_rms_px']:.3f}",
            f"{row['stereo_depth_rms_px']:.3f}",
            f"{row['stereo_thermal_rms_px']:.3f}",
            "[red]outlier[/red]" if row["outlier"] else "",
        )
    console.print(per)
    console.print(f"outliers: {rep['outlier_rule']}", highlight=False)
    if rep["dropped_outliers"]:
        console.print(f"dropped: {', '.join(rep['dropped_outliers'])}", highlight=False)
    for s in rep["skipped"]:
        console.print(f"[yellow]skipped[/yellow] {s['name']}: {s['reason']}", highlight=False)
    for u in rep["unmatched"]:
        console.print(f"[yellow]not paired[/yellow] {u['file']}: {u['reason']}", highlight=False)
    for w in rep["warnings"]:
        console.print(f"[yellow]warning:[/yellow] {w}", highlight=False)


# -- demo -----------------------------------------------------------------------------------


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
    from .app.demo import DemoConfig, run_demo

    summary = run_demo(out, DemoConfig(quick=quick), BARS)
    console.print(f"wrote {out / 'report.md'} and {out / 'report.html'}")
    for line in summary.get("findings", []):
        console.print(f"  - {line}", highlight=False)


def main() -> None:
    """Console-script entry point."""
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
