"""The command line's frame: the typer app, one-line errors (a field's error shown with its
option), the rich progress bars, and the options several commands share."""

from __future__ import annotations

import functools
import json
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

from .. import __version__
from ..errors import FieldError, ThermodepthError
from ..progress import SILENT

if TYPE_CHECKING:
    from ..conditions import Conditions
    from ..progress import Progress as Advance

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
    "pairs_per_distance": "--pairs",
    "sweep": "SWEEP",
    "depth_frames": "--depth",
    "recordings": "RECORDING",
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


def say_line(message: str) -> None:
    """A line for the user on stdout, brackets printed as they are."""
    console.print(message, markup=False, highlight=False, soft_wrap=True)


def warn_line(message: str) -> None:
    """A one-line warning on stderr, brackets printed as they are."""
    err_console.print(
        f"[yellow]warning:[/yellow] {escape(message)}", highlight=False, soft_wrap=True
    )


def print_json(data: Any) -> None:
    """Strict JSON on stdout (NaN and infinities as null, which other parsers refuse)."""
    from ..io.measurements import jsonable

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
    """A :class:`~thermodepth.progress.Reporter` drawing rich progress bars on stderr (none
    when stderr is not a terminal: a log file gets the command's lines only)."""

    @contextmanager
    def task(self, description: str, total: int | None) -> Iterator[Advance]:
        if not err_console.is_terminal:
            with SILENT.task(description, total) as advance:
                yield advance
            return
        with Progress(
            SpinnerColumn(),
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            console=err_console,
            transient=True,  # gone when the work ends: the command's own lines follow
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
DepthMode = Annotated[
    str | None,
    typer.Option(
        metavar="WxH[@FPS]",
        help="The depth camera's mode, e.g. 848x480@30 (default: the camera's recommended "
        "one: 848x480 on a D435/D455, 1280x720 on a D415; the simulated D435's 1280x720).",
    ),
]
ThermalCamera = Annotated[
    str | None,
    typer.Option(
        metavar="NAME",
        help="The simulated thermal camera: lepton3 (default), lepton3.5, lepton2.5, p2pro, "
        "boson320, boson640 (live rigs name theirs in --source: realsense+p2pro).",
    ),
]
OutDir = Annotated[Path, typer.Option("-o", "--out", help="Directory to write.")]
Seed = Annotated[int, typer.Option(help="Random seed.")]
ReportDir = Annotated[
    Path | None,
    typer.Option(help="Where to write calib_report.json/.png (default: next to --out)."),
]
BoardStyle = Annotated[
    str,
    typer.Option(
        help="How the board is made: bare (pattern painted on metal), plate (tape squares on "
        "a hot plate, hot margin) or mask (a cold mask over a warm plate)."
    ),
]
Board = Annotated[
    str, typer.Option(help="checkerboard:COLSxROWS (inner corners) or circles:COLSxROWS.")
]


def conditions_of(
    emissivity: float, ambient_temp_c: float, humidity_pct: float, reflected: float | None = None
) -> Conditions:
    """The viewing conditions the options give (FieldError names a bad one)."""
    from ..conditions import Conditions

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
