"""``emissivity``: a target ROI's emissivity measured against a reference ROI (ASTM E1933's
reference-emitter method; docs/thermography.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .base import (
    DepthMode,
    MaxSkewMs,
    ThermalCamera,
    ThermalLatencyMs,
    app,
    console,
    one_line_errors,
    warn_line,
)


@app.command("emissivity")
@one_line_errors
def emissivity_cmd(
    source: Annotated[
        str,
        typer.Argument(
            help="A live rig (realsense+lepton, ...; sim) or a recording (recording:PATH, "
            "or its path)."
        ),
    ],
    reference: Annotated[
        str, typer.Option(help="The reference ROI (tape, paint) of known emissivity.")
    ],
    target: Annotated[str, typer.Option(help="The ROI whose emissivity is measured.")],
    reference_emissivity: Annotated[
        float, typer.Option(help="The reference's emissivity, e.g. 0.95 for electrical tape.")
    ],
    settings: Annotated[
        Path, typer.Option(help="Settings YAML holding both ROIs (and the calibration).")
    ],
    tolerance: Annotated[
        float, typer.Option(help="The reference emissivity's stated tolerance, +-.")
    ] = 0.02,
    frames: Annotated[int, typer.Option(help="Frames to read and average.")] = 10,
    write: Annotated[
        bool,
        typer.Option("--write", help="Write the result into the settings file's target ROI."),
    ] = False,
    max_skew_ms: MaxSkewMs = 20.0,
    thermal_latency_ms: ThermalLatencyMs = 0.0,
    depth_mode: DepthMode = None,
    thermal_camera: ThermalCamera = None,
) -> None:
    """Measure a target ROI's emissivity against a reference ROI beside it at the same
    temperature: the reference, read at its emissivity, gives the true temperature; the
    target's emissivity is the one that reads it too (per pixel, at its own distance). Prints
    it with its standard uncertainty (the frames' spread and the reference's tolerance)."""
    from ..app.emissivity import EmissivityOptions, measure_emissivity

    options = EmissivityOptions(
        source,
        settings,
        reference,
        target,
        reference_emissivity,
        tolerance,
        frames,
        write,
        max_skew_ms / 1000.0,
        thermal_latency_ms / 1000.0,
        depth_mode,
        thermal_camera,
    )
    result = measure_emissivity(options, warn_line)
    console.print(result.estimate.line(target), soft_wrap=True, highlight=False)
    if result.written:
        console.print(f"wrote {result.written}", soft_wrap=True, highlight=False)
