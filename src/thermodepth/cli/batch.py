"""``batch``: many recordings measured again on a dask.distributed cluster."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import ThermodepthError
from .base import BARS, app, console, one_line_errors, say_line, warn_line


@app.command("batch")
@one_line_errors
def batch_cmd(
    recordings: Annotated[
        list[str],
        typer.Argument(
            metavar="RECORDING...",
            help="Recordings (.zarr): paths or fsspec URLs (file://, s3:// with s3fs).",
        ),
    ],
    out: Annotated[
        Path, typer.Option("-o", "--out", help="Folder for the results and the summary.")
    ],
    settings: Annotated[
        Path | None, typer.Option(help="Settings YAML (calibration, compensation, rules).")
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(help="Worker processes of a local cluster (default: one per core)."),
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option(help="An existing dask cluster's scheduler (tcp://HOST:8786) instead."),
    ] = None,
    resume: Annotated[
        bool, typer.Option("--resume", help="Complete the results in --out (same settings).")
    ] = False,
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="Replace an earlier batch's results in --out.")
    ] = False,
    range_pairs: Annotated[int, typer.Option(help="Pairs per task.")] = 256,
) -> None:
    """Measure recordings again on a dask cluster: per recording the files `run -o` writes,
    and a summary (Parquet, CSV, Markdown with a plot)."""
    from ..app.batch import BatchOptions, batch

    options = BatchOptions(
        tuple(recordings), out, settings, workers, scheduler, resume, overwrite, range_pairs
    )
    result = batch(options, BARS, warn_line, say_line)
    rate = result.pairs / result.wall_s if result.wall_s > 0 else 0.0
    console.print(
        f"{len(result.measured)} recordings measured ({result.pairs} pairs, {rate:.0f} pairs/s"
        f" over {result.wall_s:.1f} s), {len(result.complete)} already complete, "
        f"{len(result.failed)} failed; summary: {out / 'summary.md'}",
        soft_wrap=True,
        highlight=False,
    )
    if result.failed:
        raise ThermodepthError(
            f"{len(result.failed)} of {len(recordings)} recordings could not be measured "
            "(see above); the others are complete"
        )
