"""Point clouds with temperature: binary PLY (:mod:`thermodepth.io.ply`), one vertex per depth
pixel that has one.

Vertices: x, y, z (float32, metres, depth camera frame: x right, y down, z forward),
temperature (float32, C) and red, green, blue (uint8: the temperature through a colour map,
so viewers such as MeshLab or CloudCompare show it without set-up).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..plotting import temperature_rgb
from .ply import read_ply as read_elements
from .ply import write_ply as write_elements


def write_ply(
    path: str | Path,
    points_m: NDArray[np.floating],
    temp_c: NDArray[np.floating],
    vmin_c: float | None = None,
    vmax_c: float | None = None,
    colormap: str = "inferno",
) -> Path:
    """Write points (N, 3) with their temperatures (N,) as a binary little-endian PLY file
    (its folder made if needed).

    Args:
        path: the file.
        points_m: (N, 3) positions, m, depth camera frame.
        temp_c: (N,) temperatures, C (NaN: none).
        vmin_c, vmax_c: the colour map's range, C (default: 1st and 99th percentile).
        colormap: a matplotlib colour map's name.

    Returns:
        ``path``.
    """
    pts = np.asarray(points_m, np.float32).reshape(-1, 3)
    t = np.asarray(temp_c, np.float32).ravel()
    if len(pts) != len(t):
        raise ValueError(f"{len(pts)} points but {len(t)} temperatures")
    if vmin_c is None:
        vmin_c = float(np.nanpercentile(t, 1)) if t.size else 0.0
    if vmax_c is None:
        vmax_c = float(np.nanpercentile(t, 99)) if t.size else 1.0
    rgb = temperature_rgb(t, (vmin_c, vmax_c), colormap)
    vertex = np.empty(
        len(pts),
        dtype=[
            ("x", "f4"),
            ("y", "f4"),
            ("z", "f4"),
            ("temperature", "f4"),
            ("red", "u1"),
            ("green", "u1"),
            ("blue", "u1"),
        ],
    )
    vertex["x"], vertex["y"], vertex["z"] = pts[:, 0], pts[:, 1], pts[:, 2]
    vertex["temperature"] = t
    vertex["red"], vertex["green"], vertex["blue"] = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    return write_elements(
        path,
        {"vertex": vertex},
        ["thermodepth point cloud: metres (depth camera frame), temperature C"],
    )


def read_ply(path: str | Path) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Points (N, 3) and temperatures (N,) of a PLY written by :func:`write_ply`; a file
    that is not one is an InputError naming it."""
    v = read_elements(path, {"vertex": ("x", "y", "z", "temperature")})["vertex"]
    pts = np.stack([v["x"], v["y"], v["z"]], axis=-1).astype(np.float32)
    return pts, np.asarray(v["temperature"], np.float32)
