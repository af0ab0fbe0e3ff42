"""The ``thermodepth`` command line: thin typer commands over plain, tested functions."""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any, TypeVar

import numpy as np
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
from .errors import InputError, ThermodepthError

app = typer.Typer(
    name="thermodepth",
    help="Fuse a depth camera with a radiometric thermal camera: true temperature, in 3D.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console()
err_console = Console(stderr=True)

F = TypeVar("F", bound=Callable[..., Any])


def one_line_errors(func: F) -> F:
    """Print a ThermodepthError as one red line on stderr and exit with code 2."""

    @functools.wraps(func)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return func(*args, **kwargs)
        except ThermodepthError as exc:
            err_console.print(
                f"[red]error:[/red] {escape(str(exc))}", highlight=False, soft_wrap=True
            )
            raise typer.Exit(2) from None

    return wrapper  # type: ignore[return-value]


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


@app.command("check-calibration")
@one_line_errors
def check_calibration_cmd(
    path: Annotated[Path, typer.Argument(help="Calibration file (.yaml, .yml or .json).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Validate a calibration file and summarise it (sizes, baseline, rotation)."""
    from .calibration import Calibration

    summary = calibration_summary(Calibration.load(path))
    if as_json:
        print_json(summary)
        return
    table = Table(title=f"{path}: valid", show_header=False)
    for key, value in summary.items():
        table.add_row(key, str(value))
    console.print(table)


def calibration_summary(cal: Any) -> dict[str, Any]:
    """Human-sized facts about a calibration: sizes, FOVs, baseline mm, rotation deg, and the
    % of the depth image the thermal camera sees at 0.5, 1, 2 and 5 m."""
    return {
        "depth": f"{cal.depth.width}x{cal.depth.height}",
        "thermal": f"{cal.thermal.width}x{cal.thermal.height}",
        "depth_hfov_deg": round(cal.depth.hfov_deg, 2),
        "thermal_hfov_deg": round(cal.thermal.hfov_deg, 2),
        "depth_scale_m": cal.depth_scale_m,
        "baseline_mm": round(cal.baseline_m * 1000, 3),
        "rotation_deg": round(cal.thermal_from_depth.angle_deg, 4),
        "shared_view_pct": ", ".join(f"{z:g} m: {100 * f:.0f}" for z, f in cal.shared_view.items()),
    }


@app.command("temperature")
@one_line_errors
def temperature_cmd(
    counts: Annotated[list[float], typer.Argument(help="Raw counts (one or more).")],
    preset: Annotated[str, typer.Option(help="Planck constants preset.")] = "paper2022",
    emissivity: Annotated[float, typer.Option(help="Object emissivity (0, 1].")] = 1.0,
    distance_m: Annotated[float, typer.Option(help="Object distance, metres.")] = 0.0,
    ambient_c: Annotated[float, typer.Option(help="Air temperature, C.")] = 25.0,
    reflected_c: Annotated[
        float | None, typer.Option(help="Reflected apparent temperature, C (default: ambient).")
    ] = None,
    humidity_pct: Annotated[float, typer.Option(help="Relative humidity, percent.")] = 50.0,
    method: Annotated[str, typer.Option(help="Radiometric model: flir or thermimage.")] = "flir",
) -> None:
    """Convert raw counts to object temperature (C) with emissivity and atmosphere."""
    temps = counts_to_celsius(
        counts, preset, emissivity, distance_m, ambient_c, reflected_c, humidity_pct, method
    )
    for s, t in zip(counts, temps, strict=True):
        if math.isfinite(t):
            console.print(f"{s:g} counts -> {t:.3f} C")
        else:  # raw_to_kelvin's NaN: invalid counts, or no object signal above the offset
            console.print(f"{s:g} counts -> none (invalid, or no signal above the surroundings)")


def counts_to_celsius(
    counts: list[float],
    preset: str = "paper2022",
    emissivity: float = 1.0,
    distance_m: float = 0.0,
    ambient_c: float = 25.0,
    reflected_c: float | None = None,
    humidity_pct: float = 50.0,
    method: str = "flir",
) -> list[float]:
    """Object temperatures (C) of raw counts, parameters given at the edge in C and %."""
    from .radiometry import (
        MAX_DISTANCE_M,
        PLANCK_PRESETS,
        RADIOMETRY_METHODS,
        TEMP_LIMITS_C,
        ObjectParams,
        RadiometryParams,
        raw_to_celsius,
    )

    if preset not in PLANCK_PRESETS:
        raise InputError(f"--preset: unknown {preset!r}; choose from {sorted(PLANCK_PRESETS)}")
    if method not in RADIOMETRY_METHODS:
        raise InputError(f"--method: unknown {method!r}; choose from {sorted(RADIOMETRY_METHODS)}")
    lo, hi = TEMP_LIMITS_C
    for option, value, ok, limits in (
        ("--emissivity", emissivity, 0 < emissivity <= 1, "0 < e <= 1"),
        ("--distance-m", distance_m, 0 <= distance_m <= MAX_DISTANCE_M, f"0-{MAX_DISTANCE_M:g} m"),
        ("--ambient-c", ambient_c, lo < ambient_c <= hi, f"{lo:g} < T <= {hi:g} C"),
        ("--reflected-c", reflected_c, reflected_c is None or lo < reflected_c <= hi, "as ambient"),
        ("--humidity-pct", humidity_pct, 0 <= humidity_pct <= 100, "0-100 %"),
    ):
        if not ok:
            raise InputError(f"{option}: {value:g} is outside {limits}")
    try:
        obj = ObjectParams.from_celsius(
            emissivity, distance_m, ambient_c, humidity_pct, reflected_c
        )
    except ValueError as exc:
        raise InputError(str(exc)) from None
    params = RadiometryParams(planck=PLANCK_PRESETS[preset], obj=obj)
    return [float(t) for t in raw_to_celsius(np.asarray(counts), params, method)]


# -- simulate -------------------------------------------------------------------------------

simulate_app = typer.Typer(
    help="Simulate the D435 + Lepton 3 rig (sweeps, frames, targets).", no_args_is_help=True
)
app.add_typer(simulate_app, name="simulate")


def parse_floats(text: str, option: str) -> list[float]:
    """Comma-separated numbers of an option (``0.5,1,1.5``); InputError names the option."""
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise InputError(f"{option}: expected comma-separated numbers, got {text!r}") from None
    if not values:
        raise InputError(f"{option}: expected at least one number")
    return values


def _progress() -> Progress:
    """The commands' rich progress bar, on stderr."""
    return Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=err_console,
    )


@contextmanager
def progress_bar(description: str, total: int | None) -> Iterator[Callable[[int], None]]:
    """A rich progress bar (``total`` None: no known end); yields ``advance(n)``."""
    with _progress() as bar:
        task = bar.add_task(description, total=total)
        yield lambda n: bar.advance(task, n)


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
    ambient_c: Annotated[float, typer.Option(help="Ambient temperature, C.")] = 25.0,
    humidity_pct: Annotated[float, typer.Option(help="Relative humidity, %.")] = 50.0,
    by_vox: Annotated[
        bool, typer.Option("--by-vox", help="Average per 1 C of VOx (Tables 1-5).")
    ] = False,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """The paper's protocol: plate-centre ROI readings vs distance and VOx temperature."""
    from .sim.protocols import SweepConfig
    from .sweep import write_sweep_csv

    config = SweepConfig(
        tuple(parse_floats(distances, "--distances")),
        tuple(parse_floats(plate_temps, "--plate-temps")),
        vox_min,
        vox_max,
        samples,
        ambient_c,
        humidity_pct,
        seed=seed,
    )
    table = run_sweep(config, by_vox)
    write_sweep_csv(out, table)
    console.print(f"wrote {len(table)} rows to {out}")


def run_sweep(config: Any, by_vox: bool = False) -> Any:
    """Simulate a sweep with a progress bar; validate the config first (InputError)."""
    from .sim.protocols import aggregate_by_vox, simulate_sweep

    if config.samples < 1:
        raise InputError("--samples: must be at least 1")
    if not config.vox_min_c < config.vox_max_c:
        raise InputError("--vox-min must be below --vox-max")
    if min(config.distances_m) <= 0:
        raise InputError("--distances: must be positive")
    total = len(config.distances_m) * len(config.plate_temps_c)
    with progress_bar("sweep", total) as advance:
        table = simulate_sweep(config, progress=advance)
    return aggregate_by_vox(table) if by_vox else table


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
    from .sim.protocols import SCENES, write_frames

    if scene not in SCENES:
        raise InputError(f"--scene: unknown {scene!r}; choose from {sorted(SCENES)}")
    with progress_bar("frames", frames) as advance:
        paths = write_frames(out, SCENES[scene](), distance_m, frames, seed, advance)
    console.print(f"wrote {len(paths)} frames and calibration.yaml to {out}")


@simulate_app.command("targets")
@one_line_errors
def simulate_targets_cmd(
    out: Annotated[Path, typer.Option("-o", "--out", help="Directory to write.")],
    board: Annotated[
        str, typer.Option(help="checkerboard:COLSxROWS (inner corners) or circles:COLSxROWS.")
    ] = "checkerboard:9x6",
    square_m: Annotated[float, typer.Option(help="Square size (circle grid step), m.")] = 0.03,
    poses: Annotated[int, typer.Option(help="Number of board poses.")] = 20,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
) -> None:
    """Heated-board captures (IR + thermal per pose) for `thermodepth calibrate`."""
    from .calibration import BoardSpec
    from .sim.protocols import simulate_targets

    spec = BoardSpec.parse(board, square_m)
    with progress_bar("targets", poses) as advance:
        caps = simulate_targets(out, spec, poses, seed, progress=advance)
    console.print(f"wrote {len(caps.pairs)} pairs and {caps.calibration_path.name} to {out}")


# -- compensation -----------------------------------------------------------------------------


@app.command("fit-compensation")
@one_line_errors
def fit_compensation_cmd(
    sweep: Annotated[Path | None, typer.Argument(help="Sweep CSV (see README).")] = None,
    out: Annotated[Path, typer.Option("-o", "--out", help="Model JSON to write.")] = Path(
        "model.json"
    ),
    method: Annotated[str, typer.Option(help="radiance (ours, default) or paper.")] = "radiance",
    preset: Annotated[
        str | None,
        typer.Option(help="Write a published model instead of fitting: paper2022 (eq. 20)."),
    ] = None,
    reference_temp: Annotated[
        float | None,
        typer.Option(
            help="paper: the reference temperature (C) to fit at (default 39 if present)."
        ),
    ] = None,
    ambient_c: Annotated[
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
    from .compensation import save_model

    model = fit_compensation(
        sweep, method, preset, reference_temp, ambient_c, humidity_pct, emissivity
    )
    save_model(model, out)
    console.print(f"wrote {model.method} model to {out}")
    if model.method == "radiance":
        cv = model.cv
        scored = any(v is not None for v in cv.get("rmse_c", {}).values())
        console.print(
            f"  degrees chosen by cross-validation: {cv.get('degrees')}"
            if scored
            else f"  degrees {cv.get('degrees')}: the simplest, as nothing can be held out "
            "(one distance and one target)"
        )
        (d0, d1), (v0, v1) = model.distance_range_m, model.vox_range_c
        console.print(
            f"  fitted over {d0:g}-{d1:g} m and VOx {v0:g}-{v1:g} C; readings beyond are flagged"
        )
        if v0 == v1:
            _warn_line(
                f"{sweep}: one VOx temperature ({v0:g} C): the model cannot learn how VOx "
                "moves the readings, and flags readings at any other as vox_outside"
            )


def fit_compensation(
    sweep: Path | None,
    method: str = "radiance",
    preset: str | None = None,
    reference_temp: float | None = None,
    ambient_c: float = 25.0,
    humidity_pct: float = 50.0,
    emissivity: float = 0.95,
) -> Any:
    """A fitted (or preset) compensation model; bad input raises InputError."""
    from .compensation import PRESETS, Conditions, fit
    from .sweep import read_sweep_csv

    if preset is not None:
        if preset not in PRESETS:
            raise InputError(f"--preset: unknown {preset!r}; choose from {sorted(PRESETS)}")
        return PRESETS[preset]()
    if sweep is None:
        raise InputError("give a sweep CSV to fit, or --preset")
    if not (0 < emissivity <= 1 and 0 <= humidity_pct <= 100):
        raise InputError("--emissivity must be in (0, 1] and --humidity-pct in [0, 100]")
    table = read_sweep_csv(sweep)
    if method == "paper":
        return fit(table, "paper", reference_temp_c=reference_temp)
    return fit(table, method, conditions=Conditions(ambient_c, humidity_pct, emissivity))


@app.command("compensate")
@one_line_errors
def compensate_cmd(
    model: Annotated[Path, typer.Argument(help="Model JSON (fit-compensation).")],
    readings: Annotated[
        Path,
        typer.Argument(
            help="Readings CSV: distance_m, vox_temp_c, measured_temp_c (+ optional columns)."
        ),
    ],
    out: Annotated[Path, typer.Option("-o", "--out", help="CSV to write.")],
) -> None:
    """Add compensated_temp_c and flag columns to a readings CSV."""
    n, flagged = compensate_file(model, readings, out)
    console.print(f"wrote {n} rows to {out} ({flagged} flagged)")


def compensate_file(model_path: Path, readings: Path, out: Path) -> tuple[int, int]:
    """Compensate every row of ``readings`` into ``out``; returns (rows, rows flagged)."""
    from .compensation import apply_to_table, flag_names, load_model
    from .sweep import read_sweep_csv, write_sweep_csv

    model = load_model(model_path)
    table = read_sweep_csv(readings, required=("distance_m", "vox_temp_c", "measured_temp_c"))
    result = apply_to_table(model, table)
    flags = flag_names(result.flag)
    # digits=None: the readings' values as they came (6 digits would round them)
    write_sweep_csv(
        out, table.with_columns(compensated_temp_c=result.temp_c, flag=flags), digits=None
    )
    return len(table), sum(f != "ok" for f in flags)


@app.command("evaluate")
@one_line_errors
def evaluate_cmd(
    model: Annotated[Path, typer.Argument(help="Model JSON (fit-compensation).")],
    test: Annotated[Path, typer.Argument(help="Test sweep CSV with reference_temp_c.")],
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object on stdout.")] = False,
    by_vox: Annotated[
        bool, typer.Option("--by-vox", help="Also the layout of the paper's Tables 1-5.")
    ] = False,
    plot: Annotated[Path | None, typer.Option(help="Write Figs. 13 and 14 (PNG) here.")] = None,
) -> None:
    """Score a model on a test sweep: the paper's Table 6 metric and RMSE, max |error|, SD."""
    from .compensation import evaluation_report, load_model
    from .sweep import read_sweep_csv

    m = load_model(model)
    table = read_sweep_csv(test)
    report = evaluation_report(m, table, 1.0 if by_vox else None)
    if plot is not None:
        from .figures import plot_vox_curves

        report["figures"] = [str(p) for p in plot_vox_curves(m, table, plot)]
    if as_json:
        print_json(report)
        return
    print_scores(f"{test}: {m.method} model", report["per_distance"], report["overall"])
    if report["flags"] != {"ok": len(table)}:
        console.print(f"flags: {report['flags']}")
    print_by_vox(report.get("by_vox", []))
    for path in report.get("figures", []):
        console.print(f"wrote {path}")


def print_scores(title: str, rows: list[dict[str, Any]], total: dict[str, Any]) -> None:
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
    from .compensation import paper_tables_report

    report = paper_tables_report()
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
    from .sources import list_devices

    found = list_devices()
    if as_json:
        print_json(found)
        return
    for line in describe_devices(found):
        console.print(line, highlight=False, soft_wrap=True)


def describe_devices(found: dict[str, Any]) -> list[str]:
    """Lines for ``thermodepth devices``: each device with its source spec, a clear
    "no ... found" for each kind missing, and why RealSense devices cannot be listed when
    pyrealsense2 is unavailable."""
    lines = []
    if found.get("realsense_unavailable"):
        lines.append(f"RealSense devices cannot be listed: {found['realsense_unavailable']}")
    elif found["realsense"]:
        for d in found["realsense"]:
            lines.append(
                f"RealSense {d['name']}  serial {d['serial']}  firmware {d['firmware']}  "
                f"USB {d['usb']}  -> --source realsense:{d['serial']}"
            )
    else:
        lines.append("no RealSense device found")
    if found["purethermal"]:
        for d in found["purethermal"]:
            lines.append(
                f"PureThermal (Lepton) /dev/video{d['index']} {d['name']!r}  "
                f"-> --source lepton:{d['index']}"
            )
    else:
        others = [
            f"/dev/video{d['index']} ({d['name'] or 'unnamed'})"
            for d in found["video"]
            if not d["purethermal"]
        ]
        lines.append(
            "no PureThermal (Lepton) found"
            + (f"; other video devices: {', '.join(others)}" if others else "")
        )
    return lines


MAX_SKEW_HELP = "Pairing: drop pairs further apart in time, ms."
THERMAL_LATENCY_HELP = (
    "Lepton: subtract this from each frame's arrival time, ms (exposure to arrival; "
    "default 0: not calibrated)."
)


def _check_timing(max_skew_ms: float, thermal_latency_ms: float) -> None:
    if max_skew_ms < 0:
        raise InputError("--max-skew-ms: must be >= 0")
    if thermal_latency_ms < 0:
        raise InputError("--thermal-latency-ms: must be >= 0")


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
    max_skew_ms: Annotated[float, typer.Option(help=MAX_SKEW_HELP)] = 20.0,
    thermal_latency_ms: Annotated[float, typer.Option(help=THERMAL_LATENCY_HELP)] = 0.0,
    ir: Annotated[bool, typer.Option("--ir", help="Also record the infrared image.")] = False,
    overwrite: Annotated[
        bool, typer.Option(help="Replace an existing recording (nothing else is replaced).")
    ] = False,
) -> None:
    """Record a source into a crash-safe Zarr v3 recording (Ctrl-C stops cleanly)."""
    from .calibration import Calibration
    from .session import check_outputs, record_session
    from .sources import open_source

    if duration is not None and duration <= 0:
        raise InputError("--duration: must be > 0 seconds")
    if frames is not None and frames < 1:
        raise InputError("--frames: must be at least 1")
    if duration is None and frames is None and source.strip() == "sim":
        raise InputError("--source sim never ends: give --frames or --duration")
    _check_timing(max_skew_ms, thermal_latency_ms)
    check_outputs(record=out, overwrite=overwrite)  # before any camera starts
    cal = Calibration.load(calibration) if calibration else None
    src = open_source(
        source,
        cal,
        max_skew_s=max_skew_ms / 1000.0,
        with_ir=ir,
        thermal_latency_s=thermal_latency_ms / 1000.0,
        warn=_warn_line,
    )
    with progress_bar(f"recording {src.name}", frames) as advance:
        result = record_session(
            src,
            out,
            duration_s=duration,
            frames=frames,
            calibration=cal,
            overwrite=overwrite,
            progress=advance,
        )
    console.print(
        f"wrote {out}: {result.recorder.summary()}; stopped: {result.stopped}", soft_wrap=True
    )
    print_source_stats(result)
    if result.error:
        raise ThermodepthError(f"{result.error}; the recording keeps every frame up to then")


def _warn_line(message: str) -> None:
    err_console.print(
        f"[yellow]warning:[/yellow] {escape(message)}", highlight=False, soft_wrap=True
    )


def print_source_stats(result: Any) -> None:
    """The pairing statistics and the source's counters of a session, one line each."""
    if result.pairing is not None:
        console.print(f"pairing: {result.pairing.summary()}", soft_wrap=True, highlight=False)
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
    max_skew_ms: Annotated[float, typer.Option(help=MAX_SKEW_HELP)] = 20.0,
    thermal_latency_ms: Annotated[float, typer.Option(help=THERMAL_LATENCY_HELP)] = 0.0,
    quiet: Annotated[bool, typer.Option(help="No line per frame.")] = False,
) -> None:
    """Fuse a stream, print live measurements and alarms (Ctrl-C stops cleanly)."""
    _check_timing(max_skew_ms, thermal_latency_ms)
    result = run(
        source,
        settings,
        record,
        frames,
        out,
        None if quiet else print_frame,
        max_skew_s=max_skew_ms / 1000.0,
        thermal_latency_s=thermal_latency_ms / 1000.0,
    )
    console.print(
        f"{result.frames} frames fused ({result.shutter_frames} while the shutter was "
        f"closed), {sum(e['event'] == 'alarm' for e in result.events)} alarms; "
        f"stopped: {result.stopped}"
    )
    if result.recorder is not None:
        console.print(f"recorded to {record}: {result.recorder.summary()}", soft_wrap=True)
    print_source_stats(result)
    if result.error:
        raise InputError(result.error)


def pipeline_settings(settings_path: Path | None, settings: Any) -> dict[str, Any]:
    """What a recording made by ``run --record`` stores of the pipeline: the settings file's
    path and text, and the compensation model's path and SHA-256."""
    import hashlib

    out: dict[str, Any] = {"settings_file": None, "settings_yaml": None}
    if settings_path is not None:
        out["settings_file"] = str(settings_path)
        out["settings_yaml"] = Path(settings_path).read_text(encoding="utf-8")
    if settings.compensation is not None:
        out["compensation_model"] = str(settings.compensation)
        out["compensation_sha256"] = hashlib.sha256(
            Path(settings.compensation).read_bytes()
        ).hexdigest()
    return {"pipeline": out}


def run(
    source_spec: str,
    settings_path: Path | None,
    record: Path | None = None,
    frames: int | None = None,
    out: Path | None = None,
    on_frame: Callable[[Any], None] | None = None,
    *,
    max_skew_s: float = 0.020,
    thermal_latency_s: float = 0.0,
) -> Any:
    """Check the outputs, open the source and the pipeline, then
    :func:`thermodepth.session.run_session` (which closes the source in every case; so does
    this function when the pipeline cannot be built)."""
    from .calibration import Calibration
    from .pipeline import Pipeline, Settings
    from .session import check_outputs, run_session
    from .sources import open_source

    settings = Settings.load(settings_path) if settings_path else Settings()
    cal = Calibration.load(settings.calibration) if settings.calibration else None
    check_outputs(record=record, out_dir=out)  # before any camera starts
    src = open_source(
        source_spec,
        cal,
        frames=frames,
        max_skew_s=max_skew_s,
        thermal_latency_s=thermal_latency_s,
        warn=_warn_line,
    )
    try:
        src.require_pairs()
        # the source's calibration, else the settings'; Pipeline refuses when neither has one
        pipeline = Pipeline(settings, src.calibration or cal)
        recorded = pipeline_settings(settings_path, settings) if record else None
    except BaseException:
        src.close()
        raise
    return run_session(
        src,
        pipeline,
        frames=frames,
        record=record,
        out_dir=out,
        on_frame=on_frame,
        record_settings=recorded,
    )


def _flag_note(flags: int) -> str:
    """`` [vox_outside]``: the compensation flags a reading carries (beyond what the model
    was fitted on: a number to doubt), or nothing when it has none."""
    from .compensation import names_of
    from .pipeline import PixelFlag

    names = names_of(flags, PixelFlag)
    return f" [{', '.join(names)}]" if names else ""


def print_frame(fused: Any) -> None:
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
    board: Annotated[
        str, typer.Option(help="checkerboard:COLSxROWS (inner corners) or circles:COLSxROWS.")
    ] = "checkerboard:9x6",
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
    from .calibrate import (
        discover_pairs,
        load_depth_intrinsics,
        plot_report,
        run_calibration,
        write_report_json,
    )
    from .calibration import BoardSpec

    spec = BoardSpec.parse(board, square_m)
    fixed, scale = (None, None)
    if depth_intrinsics is not None:
        fixed, scale = load_depth_intrinsics(depth_intrinsics)
    if depth_scale_m is not None:
        if not (math.isfinite(depth_scale_m) and depth_scale_m > 0):
            raise InputError(f"--depth-scale-m: must be a finite number > 0, got {depth_scale_m}")
        scale = depth_scale_m
    listing = discover_pairs(pairs_dir)
    with progress_bar("detecting boards", len(listing.pairs)) as advance:
        result = run_calibration(
            listing,
            spec,
            depth_intrinsics=fixed,
            depth_scale_m=0.001 if scale is None else scale,
            thermal_model=thermal_model,
            depth_model=depth_model,
            thermal_refine=thermal_refine,
            drop_outliers=drop_outliers,
            progress=advance,
        )
    result.calibration.save(out)
    reports = report_dir if report_dir is not None else out.parent
    write_report_json(result, reports / "calib_report.json")
    plot_report(result, reports / "calib_report.png")
    print_calibration_report(result)
    console.print(
        f"wrote {out}, {reports / 'calib_report.json'} and {reports / 'calib_report.png'}",
        highlight=False,
    )


def print_calibration_report(result: Any) -> None:
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
        bool, typer.Option(help="Fewer poses, samples and distances (~20 s).")
    ] = False,
) -> None:
    """The whole story on the simulated rig: calibrate, reproduce the paper, generalise,
    inspect, and write report.md / report.html."""
    from .demo import STEPS, DemoConfig, run_demo

    with _progress() as bar:
        task = bar.add_task("demo", total=len(STEPS))

        def step(name: str) -> None:
            bar.update(task, description=f"demo: {name}", completed=STEPS.index(name))

        summary = run_demo(out, DemoConfig(quick=quick), step)
        bar.update(task, description="demo: done", completed=len(STEPS))
    console.print(f"wrote {out / 'report.md'} and {out / 'report.html'}")
    for line in summary.get("findings", []):
        console.print(f"  - {line}", highlight=False)


def main() -> None:
    """Console-script entry point."""
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
