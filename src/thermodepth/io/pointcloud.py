"""Point clouds with temperature: PLY (plyfile), one vertex per depth pixel that has one.

Vertices: x, y, z (float32, metres, depth camera frame: x right, y down, z forward),
temperature (float32, C) and red, green, blue (uint8: the temperature through a colour map,
so viewers such as MeshLab or CloudCompare show it without set-up).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from plyfile import PlyData, PlyElement

from ..plotting import temperature_rgb


def write_ply(
    path: str | Path,
    points_m: NDArray[np.floating],
    temp_c: NDArray[np.floating],
    vmin_c: float | None = None,
    vmax_c: float | None = None,
    colormap: str = "inferno",
    binary: bool = True,
) -> Path:
    """Write points (N, 3) with their temperatures (N,) as a PLY file.

    vmin_c / vmax_c: the colour map's range (default: 1st and 99th percentile).
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
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    PlyData(
        [PlyElement.describe(vertex, "vertex")],
        text=not binary,
        comments=["thermodepth point cloud: metres (depth camera frame), temperature C"],
    ).write(str(out))
    return out


def read_ply(path: str | Path) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Points (N, 3) and temperatures (N,) of a PLY written by :func:`write_ply`."""
    v = PlyData.read(str(path))["vertex"]
    pts = np.stack([v["x"], v["y"], v["z"]], axis=-1).astype(np.float32)
    return pts, np.asarray(v["temperature"], np.float32)
