"""The ``thermodepth`` command line: thin typer commands over plain, tested functions."""

from __future__ import annotations

import functools
import json
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, TypeVar

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from . import __version__
from .errors import ThermodepthError

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
            err_console.print(f"[red]error:[/red] {exc}", highlight=False, soft_wrap=True)
            raise typer.Exit(2) from None

    return wrapper  # type: ignore[return-value]


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
        print(json.dumps(summary, indent=2))
        return
    table = Table(title=f"{path}: valid", show_header=False)
    for key, value in summary.items():
        table.add_row(key, str(value))
    console.print(table)


def calibration_summary(cal: Any) -> dict[str, Any]:
    """Human-sized facts about a calibration: sizes, FOVs, baseline mm, rotation deg."""
    t = cal.thermal_from_depth
    angle = np.degrees(np.arccos(np.clip((np.trace(t.rotation) - 1) / 2, -1, 1)))

    def hfov(c: Any) -> float:
        return round(float(np.degrees(2 * np.arctan(c.width / 2 / c.fx))), 2)

    return {
        "depth": f"{cal.depth.width}x{cal.depth.height}",
        "thermal": f"{cal.thermal.width}x{cal.thermal.height}",
        "depth_hfov_deg": hfov(cal.depth),
        "thermal_hfov_deg": hfov(cal.thermal),
        "depth_scale_m": cal.depth_scale_m,
        "baseline_mm": round(cal.baseline_m * 1000, 3),
        "rotation_deg": round(float(angle), 4),
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
        console.print(f"{s:g} counts -> {t:.3f} C")


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
    from .errors import InputError
    from .radiometry import (
        PLANCK_PRESETS,
        RADIOMETRY_METHODS,
        ObjectParams,
        RadiometryParams,
        celsius_to_kelvin,
        raw_to_celsius,
    )

    if preset not in PLANCK_PRESETS:
        raise InputError(f"--preset: unknown {preset!r}; choose from {sorted(PLANCK_PRESETS)}")
    if method not in RADIOMETRY_METHODS:
        raise InputError(f"--method: unknown {method!r}; choose from {sorted(RADIOMETRY_METHODS)}")
    try:
        obj = ObjectParams(
            emissivity=emissivity,
            distance_m=distance_m,
            reflected_temp_k=float(
                celsius_to_kelvin(ambient_c if reflected_c is None else reflected_c)
            ),
            atmosphere_temp_k=float(celsius_to_kelvin(ambient_c)),
            relative_humidity=humidity_pct / 100.0,
        )
    except ValueError as exc:
        raise InputError(str(exc)) from None
    params = RadiometryParams(planck=PLANCK_PRESETS[preset], obj=obj)
    return [float(t) for t in raw_to_celsius(np.asarray(counts), params, method)]


def main() -> None:
    """Console-script entry point."""
    app()


if __name__ == "__main__":  # pragma: no cover
    main()
