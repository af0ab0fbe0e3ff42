"""``export``: what a run measured, as a ROS bag for Foxglove and ROS tools."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import ThermodepthError
from .base import app, console, one_line_errors, warn_line
from .measure import print_outputs


@app.command("export")
@one_line_errors
def export_cmd(
    source: Annotated[
        str, typer.Argument(help="Any --source spec: recording:PATH, rosbag:PATH, sim, ...")
    ],
    out: Annotated[Path, typer.Argument(help="The new bag: a .mcap file, or a folder/.bag.")],
    settings: Annotated[
        Path | None, typer.Option(help="Settings YAML (calibration, compensation, rules).")
    ] = None,
    frames: Annotated[int | None, typer.Option(help="Stop after this many pairs.")] = None,
    bag_format: Annotated[
        str,
        typer.Option(
            "--format",
            help="mcap (ROS 2 messages, one file), rosbag2 (a folder with .db3), rosbag2-mcap "
            "(a folder with .mcap), ros1 (a .bag).",
        ),
    ] = "mcap",
    compression: Annotated[
        str, typer.Option(help="none, lz4 or zstd (mcap); zstd (rosbag2-mcap); lz4 (ros1).")
    ] = "none",
    cloud_points: Annotated[
        int, typer.Option(help="The most points of a fused frame's cloud (every k-th kept).")
    ] = 100_000,
    temperature_image: Annotated[
        str,
        typer.Option(
            help="The temperature on the depth grid as 32FC1 (C, for ROS tools), 16UC1 "
            "(centikelvin, what Foxglove colours) or both.",
        ),
    ] = "both",
) -> None:
    """Fuse a source into a ROS bag that Foxglove and ROS tools open (docs/ros.md): depth,
    raw thermal, camera_info, /tf_static, the sensor temperature, the temperature on the
    depth grid, a point cloud with a temperature field, hotspot markers, measurements and
    alarms as JSON."""
    from ..app.run import RunOptions, run
    from ..io.ros import COMPRESSIONS, FORMATS
    from ..sinks.bag import TEMPERATURE_IMAGES, BagSink

    for name, value, allowed in (("--format", bag_format, FORMATS),
                                 ("--compression", compression, COMPRESSIONS),
                                 ("--temperature-image", temperature_image,
                                  TEMPERATURE_IMAGES)):  # fmt: skip
        if value not in allowed:
            raise ThermodepthError(f"{name} {value}: expected one of {', '.join(allowed)}")
    sink = BagSink(out, bag_format, compression, cloud_points, temperature_image=temperature_image)
    result = run(RunOptions(source, settings, frames), [sink], warn_line)
    console.print(f"{result.frames} frames fused; stopped: {result.stopped}")
    print_outputs(result)
    if result.error:
        raise ThermodepthError(result.error)
