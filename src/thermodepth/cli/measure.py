"""``devices``, ``record``, ``run`` and ``view``: cameras, recordings and the live measuring
run. (The always-on monitor and its dashboard: :mod:`.monitor`; ROS bags: :mod:`.ros`.)"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer
from rich.markup import escape

from ..errors import ThermodepthError
from .base import (
    BARS,
    DepthMode,
    MaxSkewMs,
    ThermalCamera,
    ThermalLatencyMs,
    app,
    console,
    one_line_errors,
    print_json,
    warn_line,
)

if TYPE_CHECKING:
    from ..pipeline import FusedFrame
    from ..sinks import SessionResult


@app.command("devices")
@one_line_errors
def devices_cmd(
    as_json: Annotated[bool, typer.Option("--json", help="Print as JSON.")] = False,
) -> None:
    """List attached RealSense cameras and thermal cameras (PureThermal Lepton, InfiRay P2
    Pro / Topdon TC001, FLIR Boson), each with the --source that opens it."""
    from ..app.devices import describe_devices, list_devices

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
            help="sim, realsense[:SERIAL|:FILE], lepton[:N], p2pro[:N], boson[:N], "
            "realsense+lepton (any depth + thermal camera), recording:PATH, folder:PATH, "
            "rosbag:PATH.",
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
    depth: Annotated[
        str,
        typer.Option(
            "--depth",
            metavar="all|paired",
            help="Depth frames to keep: all (30 fps), or only those that pair with a thermal "
            "frame (8.7 fps, 3.4x less to store; all that a replay measures).",
        ),
    ] = "all",
    codec: Annotated[
        str,
        typer.Option(
            "--codec",
            metavar="lz4|zstd",
            help="Image compression (lossless): lz4 encodes and decodes 2.6-4.2x faster (replays "
            "faster); zstd stores 6-33 % less.",
        ),
    ] = "lz4",
    depth_mode: DepthMode = None,
    thermal_camera: ThermalCamera = None,
) -> None:
    """Record a source into a crash-safe Zarr v3 recording (Ctrl-C stops cleanly)."""
    from ..app.record import RecordOptions, record

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
        depth,
        codec,
        depth_mode,
        thermal_camera,
    )
    result = record(options, BARS, warn_line)
    console.print(
        f"wrote {out}: {result.recorder.summary()}; stopped: {result.stopped}", soft_wrap=True
    )
    print_source_stats(result)
    if result.error:
        raise ThermodepthError(f"{result.error}; the recording keeps every frame up to then")


def print_outputs(result: SessionResult) -> None:
    """What the session's sinks wrote and where, one line each."""
    for line in result.outputs:
        console.print(line, soft_wrap=True, highlight=False)


def print_source_stats(result: SessionResult) -> None:
    """The pairing statistics and the source's counters of a session, one line each."""
    if result.pairing is not None:
        by = f" (paired by {result.pairing_by})" if result.pairing_by else ""
        line = result.pairing.summary() if not result.pairing_by else result.pairing.skew_summary()
        console.print(f"pairing{by}: {line}", soft_wrap=True, highlight=False)
    if result.counters:
        counts = ", ".join(f"{k} {v}" for k, v in result.counters.items())
        console.print(f"source: {counts}", soft_wrap=True, highlight=False)


ViewerSave = Annotated[
    Path | None,
    typer.Option("--viewer-save", help="Write the rerun view to this .rrd file instead."),
]
ViewerConnect = Annotated[
    str | None,
    typer.Option(
        "--viewer-connect",
        metavar="ADDR",
        help="Stream the view to a running rerun viewer (rerun+http://HOST:9876/proxy).",
    ),
]


@app.command("run")
@one_line_errors
def run_cmd(
    source: Annotated[
        str,
        typer.Option(
            help="Where frames come from: sim, realsense+lepton (any depth + thermal camera: "
            "realsense+p2pro, realsense+boson), recording:PATH, folder:PATH, rosbag:PATH "
            "(see README)."
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
            "-o",
            "--out",
            help="Write measurements.jsonl, alarms.jsonl and hotspots.csv here (with line or "
            "isotherm ROIs, lines.csv and isotherms.csv too).",
        ),
    ] = None,
    max_skew_ms: MaxSkewMs = 20.0,
    thermal_latency_ms: ThermalLatencyMs = 0.0,
    quiet: Annotated[bool, typer.Option("--quiet", help="No line per frame.")] = False,
    mqtt: Annotated[
        str | None,
        typer.Option(
            metavar="mqtt://[USER@]HOST[:PORT]/PREFIX",
            help="Publish alarms, measurements and status to this MQTT broker (mqtts:// for "
            "TLS); the password from THERMODEPTH_MQTT_PASSWORD or the settings' "
            "mqtt.password_file.",
        ),
    ] = None,
    viewer: Annotated[
        bool, typer.Option("--viewer", help="Show the run live in 3D in a rerun viewer.")
    ] = False,
    viewer_save: ViewerSave = None,
    viewer_connect: ViewerConnect = None,
    snapshots: Annotated[
        int | None,
        typer.Option(
            metavar="N",
            help="With --out: an overlay PNG and a PLY every N frames and at every alarm.",
        ),
    ] = None,
    depth_mode: DepthMode = None,
    thermal_camera: ThermalCamera = None,
    foxglove: Annotated[
        str | None,
        typer.Option(
            metavar="HOST:PORT",
            help="Serve the run live to Foxglove (foxglove extra), e.g. 127.0.0.1:8765: "
            "ROS 2 messages as export writes them, each topic at most 5 a second.",
        ),
    ] = None,
) -> None:
    """Fuse a stream, print live measurements and alarms (Ctrl-C stops cleanly)."""
    from ..alarms import RAISED
    from ..app.run import RunOptions, run
    from ..sinks import CallbackSink

    options = RunOptions(
        source,
        settings,
        frames,
        out,
        record,
        max_skew_ms / 1000.0,
        thermal_latency_ms / 1000.0,
        mqtt=mqtt,
        viewer=viewer,
        viewer_save=viewer_save,
        viewer_connect=viewer_connect,
        snapshots=snapshots,
        depth_mode=depth_mode,
        thermal_camera=thermal_camera,
        foxglove=foxglove,
    )
    result = run(options, [] if quiet else [CallbackSink(print_frame)], warn_line)
    console.print(
        f"{result.frames} frames fused ({result.shutter_frames} while the shutter was "
        f"closed), {sum(e['event'] in RAISED for e in result.events)} alarms; "
        f"stopped: {result.stopped}"
    )
    print_outputs(result)
    print_source_stats(result)
    if result.error:
        raise ThermodepthError(result.error)


@app.command("view")
@one_line_errors
def view_cmd(
    recording: Annotated[
        str,
        typer.Argument(
            metavar="RECORDING|SOURCE",
            help="A recording (.zarr) to replay, or any source spec (folder:PATH, sim, ...).",
        ),
    ],
    settings: Annotated[
        Path | None, typer.Option(help="Settings YAML (calibration, compensation, rules).")
    ] = None,
    save: ViewerSave = None,
    connect: ViewerConnect = None,
) -> None:
    """Replay a recording (or any source) through the pipeline into the rerun viewer (spawned,
    unless it is saved to a file or sent to a running viewer)."""
    from ..app.run import RunOptions, run, spec_of

    options = RunOptions(
        spec_of(recording),
        settings,
        viewer=save is None and connect is None,
        viewer_save=save,
        viewer_connect=connect,
    )
    result = run(options, [], warn_line)
    print_outputs(result)
    if result.error:
        raise ThermodepthError(result.error)


def _flag_note(flags: int) -> str:
    """`` [vox_outside]``: the compensation flags a reading carries (beyond what the model
    was fitted on: a number to doubt), or nothing when it has none."""
    from ..compensation import names_of
    from ..pipeline import PixelFlag

    names = names_of(flags, PixelFlag)
    return f" [{', '.join(names)}]" if names else ""


def print_frame(fused: FusedFrame) -> None:
    """One line per fused frame: time, VOx, the hottest hotspot, ROIs, alarms."""
    from ..alarms import event_line

    if fused.in_ffc:
        console.print(
            f"[dim]frame {fused.index:5d}  t={fused.thermal_time_s:8.2f} s  shutter "
            "closed (FFC): not measured[/dim]"
        )
        return
    parts = [f"frame {fused.index:5d}  t={fused.thermal_time_s:8.2f} s  VOx {fused.vox_label}"]
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
        style = "bold red" if e["event"] in ("alarm", "escalated") else "green"
        console.print(f"[{style}]{escape(event_line(e))}[/{style}]")
