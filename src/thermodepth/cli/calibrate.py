"""``check-calibration``, ``calibrate`` and ``calibrate-camera``: calibration files, the pair
of cameras, one camera."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer
from rich.markup import escape
from rich.table import Table

from ..errors import ThermodepthError
from .base import (
    BARS,
    Board,
    DepthMode,
    MaxSkewMs,
    ReportDir,
    ThermalLatencyMs,
    app,
    console,
    one_line_errors,
    print_json,
    warn_line,
)

if TYPE_CHECKING:
    from ..calibrate import CalibrationResult, CameraResult


@app.command("check-calibration")
@one_line_errors
def check_calibration_cmd(
    path: Annotated[Path, typer.Argument(help="Calibration file (.yaml, .yml or .json).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Validate a calibration file and summarise it (sizes, baseline, rotation)."""
    from ..app.calibrate import check_calibration

    summary = check_calibration(path)
    if as_json:
        print_json(summary)
        return
    table = Table(title=f"{path}: valid", show_header=False)
    for key, value in summary.items():
        table.add_row(key, str(value))
    console.print(table)


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
    report_dir: ReportDir = None,
    thermal_intrinsics: Annotated[
        Path | None,
        typer.Option(
            help="Hold the thermal camera's intrinsics fixed: the file calibrate-camera wrote "
            "(many thermal views fit them best), or a calibration file (its thermal section)."
        ),
    ] = None,
    thermal_output: Annotated[
        str,
        typer.Option(
            metavar="counts|kelvin:SCALE[:OFFSET]",
            help="What the thermal camera's pixels are, written as thermal.output: raw counts "
            "(counts:16 for 16 bits), or its own temperature, kelvin = value x SCALE + OFFSET "
            "(a Boson in TLinear: kelvin:0.01; a Lepton's TLinear and a P2 Pro say it in "
            "their frames).",
        ),
    ] = "counts",
) -> None:
    """Calibrate the depth + thermal pair from board captures: thermal (and depth)
    intrinsics and thermal_from_depth, with a quality report."""
    from ..app.calibrate import CalibrateOptions, calibrate

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
        thermal_intrinsics,
        thermal_output,
    )
    outcome = calibrate(options, BARS)
    print_calibration_report(outcome.result)
    console.print(f"wrote {', '.join(map(str, outcome.files))}", highlight=False)


@app.command("calibrate-camera")
@one_line_errors
def calibrate_camera_cmd(
    images_dir: Annotated[
        Path,
        typer.Argument(
            help="Folder of single views of the board (in a folder of pairs, the camera's "
            "own: *_thermal or right*; *_ir, *_color, *_rgb or left*); PNG, TIFF, JPEG, .npy."
        ),
    ],
    square_m: Annotated[
        float, typer.Option("--square-m", help="Square size (circle grid step), metres.")
    ],
    board: Board = "checkerboard:9x6",
    out: Annotated[
        Path, typer.Option("-o", "--out", help="Camera file to write (its intrinsics).")
    ] = Path("thermal.yaml"),
    camera: Annotated[
        str, typer.Option(help="thermal, or depth (the depth camera's IR or colour images).")
    ] = "thermal",
    model: Annotated[
        str | None,
        typer.Option(
            help="Distortion terms: no-k3, radial, full or none (default: no-k3 "
            "thermal, radial depth)."
        ),
    ] = None,
    refine: Annotated[
        str | None,
        typer.Option(
            help="Corner refinement: homography or cornersubpix (default: homography "
            "thermal, cornersubpix depth)."
        ),
    ] = None,
    drop_outliers: Annotated[
        bool, typer.Option("--drop-outliers", help="Fit again without the outlier images.")
    ] = False,
    report_dir: ReportDir = None,
) -> None:
    """Calibrate one camera's intrinsics from single views of a board (use them with
    calibrate --thermal-intrinsics), with a quality report."""
    from ..app.calibrate import CameraOptions, calibrate_camera

    options = CameraOptions(
        images_dir, square_m, board, out, camera, model, refine, drop_outliers, report_dir
    )
    outcome = calibrate_camera(options, BARS)
    print_camera_report(outcome.result)
    console.print(f"wrote {', '.join(map(str, outcome.files))}", highlight=False)


@app.command("capture-board")
@one_line_errors
def capture_board_cmd(
    source: Annotated[
        str,
        typer.Option(
            help="Both cameras with the IR image: realsense+lepton (any depth + thermal "
            "camera), or recording:PATH (recorded with --ir)."
        ),
    ],
    square_m: Annotated[
        float, typer.Option("--square-m", help="Square size (circle grid step), metres.")
    ],
    out: Annotated[
        Path, typer.Option("-o", "--out", help="Folder of pairs (numbering continues).")
    ],
    board: Board = "checkerboard:9x6",
    count: Annotated[int, typer.Option(help="Stop after so many pairs kept.")] = 25,
    max_skew_ms: MaxSkewMs = 20.0,
    thermal_latency_ms: ThermalLatencyMs = 0.0,
    depth_mode: DepthMode = None,
) -> None:
    """Keep the pairs of a stream worth calibrating with: the whole board in both images,
    held still, shutter open, a new region or tilt (Ctrl-C stops, keeping every pair)."""
    from ..app.capture import CaptureOptions, capture_board, verdict_lines

    options = CaptureOptions(
        source,
        out,
        square_m,
        board,
        count,
        max_skew_ms / 1000.0,
        thermal_latency_ms / 1000.0,
        depth_mode,
    )
    result = capture_board(options, BARS, warn_line)
    console.print(
        f"kept {len(result.kept)} pairs in {out} (the board's corners cover "
        f"{result.coverage:.0%} of the thermal image) of {result.examined} examined: "
        f"{', '.join(verdict_lines(result))}; stopped: {result.stopped}",
        highlight=False,
        soft_wrap=True,
    )
    if not result.kept:
        warn_line(
            f"no pair kept: the board was never seen whole and still in both images; check "
            f"--board ({board} counts inner corners) and --square-m"
        )
    if result.error:
        raise ThermodepthError(f"{result.error}; every pair kept up to then is in {out}")


def print_camera_report(result: CameraResult) -> None:
    """The terminal report of one camera's calibration."""
    rep = result.report_dict()
    fit = rep["fit"]
    table = Table(
        title=f"{rep['camera']} camera from {rep['images_used']} of {rep['images_found']} "
        f"images ({rep['board']})",
        show_header=False,
    )
    table.add_row("size px", "{}x{}".format(*fit["size"]))
    table.add_row("distortion model", fit["model"])
    table.add_row("RMS px", f"{fit['rms_px']:.3f}")
    for key in ("fx", "fy", "cx", "cy"):
        table.add_row(key, f"{fit[key]:.2f}")
    table.add_row("distortion k1 k2 p1 p2 k3", " ".join(f"{k:.4g}" for k in fit["distortion"]))
    table.add_row("corner coverage", f"{rep['coverage']['fraction']:.0%}")
    console.print(table)
    outliers = [r["file"] for r in rep["per_image"] if r["outlier"]]
    console.print(
        f"per image RMS px: median {np.median([r['rms_px'] for r in rep['per_image']]):.3f}, "
        f"outliers: {', '.join(outliers) or 'none'} ({rep['outlier_rule']})",
        highlight=False,
        soft_wrap=True,
    )
    if rep["dropped_outliers"]:
        console.print(f"dropped: {', '.join(rep['dropped_outliers'])}", highlight=False)
    for s in rep["skipped"]:
        console.print(
            f"[yellow]skipped[/yellow] {s['file']}: {escape(s['reason'])}", highlight=False
        )
    for w in rep["warnings"]:
        console.print(f"[yellow]warning:[/yellow] {escape(w)}", highlight=False)


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
