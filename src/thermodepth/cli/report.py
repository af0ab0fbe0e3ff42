"""``report``: the inspection report of a period, from a monitor's event store."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .base import app, console, one_line_errors


@app.command("report")
@one_line_errors
def report_cmd(
    config: Annotated[Path, typer.Argument(help="The monitor's config (monitor.yaml).")],
    start: Annotated[
        str,
        typer.Option(
            "--from", help="First day (YYYY-MM-DD, UTC) or an instant (ISO 8601, UTC unless told)."
        ),
    ],
    end: Annotated[
        str, typer.Option("--to", help="Last day, included (YYYY-MM-DD), or an instant.")
    ],
    out: Annotated[
        Path, typer.Option("-o", "--out", help="The report: a .pdf or a self-contained .html.")
    ] = Path("report.pdf"),
) -> None:
    """Write the inspection report of a period (docs/monitor.md, Reports): per rig and ROI
    the readings (max, mean, min in °C, a trend), every event with its picture and who
    acknowledged it, the viewing conditions and the calibration."""
    from ..app.report import make_report

    report = make_report(config, start, end, out)
    empty = " (nothing recorded in the period)" if report.empty else ""
    console.print(
        f"{out}: {len(report.rigs)} rigs, {report.events} events, {report.period.label()}{empty}",
        markup=False,
        highlight=False,
        soft_wrap=True,
    )
