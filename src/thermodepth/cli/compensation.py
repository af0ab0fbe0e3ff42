"""``temperature``, ``collect-sweep``, ``fit-compensation``, ``compensate``, ``evaluate`` and
``paper-tables``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table

from ..errors import ThermodepthError
from .base import (
    BARS,
    AmbientTempC,
    DepthMode,
    Emissivity,
    HumidityPct,
    MaxSkewMs,
    ReflectedTempC,
    ThermalCamera,
    ThermalLatencyMs,
    app,
    conditions_of,
    console,
    one_line_errors,
    print_json,
    say_line,
    warn_line,
)


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
    from ..app.temperature import counts_to_celsius

    conditions = conditions_of(emissivity, ambient_temp_c, humidity_pct, reflected_temp_c)
    temps = counts_to_celsius(counts, conditions, distance_m, preset, method)
    for s, t in zip(counts, temps, strict=True):
        if math.isfinite(t):
            console.print(f"{s:g} counts -> {t:.3f} C")
        else:  # raw_to_kelvin's NaN: invalid counts, or no object signal above the offset
            console.print(f"{s:g} counts -> none (invalid, or no signal above the surroundings)")


@app.command("collect-sweep")
@one_line_errors
def collect_sweep_cmd(
    out: Annotated[Path, typer.Option("-o", "--out", help="Sweep CSV to write.")],
    reference_temp_c: Annotated[
        float | None,
        typer.Option(help="The plate's true temperature, C (its contact thermometer)."),
    ] = None,
    source: Annotated[
        str,
        typer.Option(
            help="realsense+lepton (live: any depth + thermal camera), recording:PATH, "
            "folder:PATH, rosbag:PATH, or sim (see README)."
        ),
    ] = "realsense+lepton",
    target: Annotated[
        str,
        typer.Option(
            help="auto (the plate: flat, uniform, near the reference temperature), "
            "rect:U0,V0,U1,V1 (thermal pixels) or depth-range:NEAR,FAR (Z, m)."
        ),
    ] = "auto",
    average: Annotated[int, typer.Option(help="Readings averaged into each row.")] = 1,
    emissivity: Emissivity = 0.95,
    ambient_temp_c: AmbientTempC = 25.0,
    humidity_pct: HumidityPct = 50.0,
    append: Annotated[
        bool, typer.Option("--append", help="Add rows to an existing sweep CSV.")
    ] = False,
    calibration: Annotated[
        Path | None,
        typer.Option(help="The rig's calibration file (a recording keeps its own)."),
    ] = None,
    frames: Annotated[int | None, typer.Option(help="Stop after so many pairs.")] = None,
    max_skew_ms: MaxSkewMs = 20.0,
    thermal_latency_ms: ThermalLatencyMs = 0.0,
    depth_mode: DepthMode = None,
    thermal_camera: ThermalCamera = None,
) -> None:
    """Read the reference plate in every pair (distance from the depth camera, VOx from the
    telemetry, mean reading), one sweep CSV row per --average pairs, each on disk as it is
    made (Ctrl-C keeps them): the input of fit-compensation."""
    from ..app.collect import CollectOptions, collect_sweep
    from .measure import print_outputs, print_source_stats

    options = CollectOptions(
        source,
        out,
        reference_temp_c,
        target,
        average,
        conditions_of(emissivity, ambient_temp_c, humidity_pct),
        append,
        calibration,
        frames,
        max_skew_ms / 1000.0,
        thermal_latency_ms / 1000.0,
        depth_mode,
        thermal_camera,
    )
    result = collect_sweep(options, BARS, warn_line, say_line)
    print_outputs(result)
    print_source_stats(result)
    if result.error:
        raise ThermodepthError(f"{result.error}; {out} keeps every row up to then")


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
    from ..app.compensation import fit_compensation

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
    from ..app.compensation import compensate_file

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
    from ..app.compensation import evaluate

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
            f"{r['distance_m']:.3g}",
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
    from ..app.compensation import paper_tables

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
