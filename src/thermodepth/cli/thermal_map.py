"""``thermodepth map``: a walk-around fused into a 3D thermal model (docs/mapping.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from .base import (
    BARS,
    DepthMode,
    MaxSkewMs,
    ThermalCamera,
    ThermalLatencyMs,
    app,
    console,
    one_line_errors,
    warn_line,
)


@app.command("map")
@one_line_errors
def map_cmd(
    source: Annotated[
        str, typer.Argument(help="A recording, or any --source spec (folder:PATH, rosbag:PATH).")
    ],
    out: Annotated[Path, typer.Option("-o", "--out", help="The model's folder (new or empty).")],
    settings: Annotated[
        Path | None,
        typer.Option(help="Settings YAML (calibration, radiometry, compensation, hotspots)."),
    ] = None,
    trajectory: Annotated[
        Path | None,
        typer.Option(
            help="The depth camera's poses as a TUM file (timestamp tx ty tz qx qy qz qw, on "
            "the frames' clock); default: depth odometry with loop closure."
        ),
    ] = None,
    odometry_fps: Annotated[
        float,
        typer.Option(
            help="Depth odometry tracks every n-th depth frame of a faster camera, the poses "
            "between interpolated."
        ),
    ] = 15.0,
    voxel_m: Annotated[float, typer.Option(help="Voxel size, m.")] = 0.01,
    max_range_m: Annotated[float, typer.Option(help="Depth beyond this is not fused, m.")] = 3.0,
    method: Annotated[
        str,
        typer.Option(
            help="How each surface's views become its temperature: median (weighted), "
            "trimmed (weighted mean of the middle half), mean (weighted), plain (unweighted "
            "mean of every view, no physics: the baseline)."
        ),
    ] = "median",
    max_angle_deg: Annotated[
        float, typer.Option(help="Views further than this from a surface's normal are not used.")
    ] = 60.0,
    directional: Annotated[
        bool,
        typer.Option(
            help="Correct each view for the emissivity at its angle (Fresnel, from the "
            "settings' emissivity at normal incidence)."
        ),
    ] = True,
    every: Annotated[int, typer.Option(help="Use every n-th thermal frame.")] = 1,
    hotspot_c: Annotated[
        float | None, typer.Option(help="Hotspot threshold, C (default: the settings').")
    ] = None,
    palette: Annotated[str, typer.Option(help="The colour scale of the files and pictures.")] = (
        "inferno"
    ),
    viewer_save: Annotated[
        Path | None, typer.Option(help="Also write the model for rerun (an .rrd file).")
    ] = None,
    max_skew_ms: MaxSkewMs = 20.0,
    thermal_latency_ms: ThermalLatencyMs = 0.0,
    depth_mode: DepthMode = None,
    thermal_camera: ThermalCamera = None,
) -> None:
    """Fuse a walk-around into a 3D model whose surface carries its true temperature:
    mesh.ply (scalar_temperature, scalar_weight, scalar_views, scalar_spread, ...),
    model.glb, trajectory.tum, hotspots.csv, map_report.json and a report with views."""
    from ..app.map import MapOptions, build_map
    from ..mapping.fusion import FusionOptions

    options = MapOptions(
        source,
        out,
        settings,
        trajectory,
        odometry_fps,
        voxel_m,
        max_range_m,
        FusionOptions(max_angle_deg=max_angle_deg, method=method, directional=directional),
        every,
        hotspot_c,
        palette,
        viewer_save,
        max_skew_ms / 1000.0,
        thermal_latency_ms / 1000.0,
        depth_mode,
        thermal_camera,
    )
    result = build_map(options, BARS, warn_line)
    r = result.report
    m, w = r["mesh"], r["walk"]
    console.print(
        f"model of {m['vertices']:,} vertices, {m['area_m2']:.2f} m2, "
        f"{m['with_temperature']:.0%} with a temperature, from {w['views_used']} of "
        f"{w['views']} thermal views; {len(result.hotspots)} hotspots; "
        f"{r['seconds']['total']:.1f} s for a {w['duration_s']:.1f} s walk"
    )
    for k, h in enumerate(result.hotspots[:5], 1):
        x, y, z = h.centre_m
        console.print(
            f"  hotspot {k}: peak {h.peak_c:.1f} C at ({x:.3f}, {y:.3f}, {z:.3f}) m, "
            f"{h.area_m2 * 1e4:.1f} cm2"
        )
    truth = r.get("against_truth")
    if truth:
        t = truth["temperature"].get("fused", {})
        console.print(
            f"against the truth: ATE {truth['trajectory'].get('rmse_m', float('nan')):.3f} m, "
            f"Chamfer {truth['geometry']['chamfer_m']:.3f} m, F-score "
            f"{truth['geometry']['f_score']:.2f}, coverage {truth['coverage']:.0%}, "
            f"temperature MAE {t.get('mae_c', float('nan')):.2f} C"
        )
    console.print(f"wrote {out}")
