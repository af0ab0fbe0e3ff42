"""A thermal model's files: the mesh as PLY with the temperature and its quality per vertex,
and as glTF binary (GLB) for viewers and the web.

PLY (binary little endian): vertex x, y, z (float, m), nx, ny, nz, red, green, blue
(the colour scale of the report) and float properties ``scalar_temperature`` (C),
``scalar_weight``, ``scalar_views``, ``scalar_spread`` (C), ``scalar_best`` (C, the nearest
view's) and ``scalar_last_seen`` (s): CloudCompare lists properties named ``scalar_*`` as
scalar fields without asking. Faces: ``vertex_indices`` lists.

GLB (trimesh): positions, normals, ``COLOR_0`` (the same colours) and the temperature as a
float vertex attribute ``_TEMPERATURE`` (glTF 2.0 section 3.7.2.1: application-specific
attributes start with an underscore), NaN where the surface has none; the scale in the
scene's ``extras``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..plotting import temperature_rgb
from .ply import read_ply, write_ply

FloatArray = NDArray[np.float64]
SCALARS = ("temperature", "weight", "views", "spread", "best", "last_seen")
"""The PLY's ``scalar_<name>`` properties, in order."""


def temperature_colours(
    temp_c: FloatArray, range_c: tuple[float, float], colormap: str
) -> NDArray[np.uint8]:
    """RGB (V, 3) of temperatures (V,) on one scale; grey where there is none."""
    rgb = temperature_rgb(np.nan_to_num(temp_c, nan=range_c[0]), range_c, colormap)
    rgb = np.asarray(rgb, np.uint8).reshape(-1, 3).copy()
    rgb[~np.isfinite(temp_c)] = 128
    return rgb


def write_model_ply(
    path: Path,
    vertices: FloatArray,
    triangles: NDArray[np.int64],
    normals: FloatArray,
    rgb: NDArray[np.uint8],
    scalars: dict[str, NDArray[Any]],
) -> Path:
    """The mesh (vertices and normals (V, 3), triangles (F, 3), colours (V, 3)) with its
    per-vertex ``scalars`` (V,) named as :data:`SCALARS` (module docstring) at ``path``:
    the header, then both elements as two packed arrays (a million faces in a second)."""
    if set(scalars) != set(SCALARS):
        raise ValueError(f"scalars {sorted(scalars)}: give {list(SCALARS)}")
    fields = [(c, "<f4") for c in ("x", "y", "z", "nx", "ny", "nz")]
    fields += [(c, "u1") for c in ("red", "green", "blue")]
    fields += [(f"scalar_{name}", "<f4") for name in SCALARS]
    vertex = np.empty(len(vertices), dtype=fields)
    for k, c in enumerate("xyz"):
        vertex[c] = vertices[:, k]
        vertex[f"n{c}"] = normals[:, k]
    for k, c in enumerate(("red", "green", "blue")):
        vertex[c] = rgb[:, k]
    for name in SCALARS:
        vertex[f"scalar_{name}"] = scalars[name]
    faces = np.empty(len(triangles), dtype=[("vertex_indices", "<i4", (3,))])
    faces["vertex_indices"] = triangles
    comment = "thermodepth thermal model: metres (world), temperatures C, times s"
    return write_ply(path, {"vertex": vertex, "face": faces}, [comment])


def read_model_ply(path: Path) -> dict[str, NDArray[Any]]:
    """A model PLY's vertices (V, 3), triangles (F, 3) and scalars by name (V,); a file
    that is not one is an InputError naming it."""
    need = {
        "vertex": ("x", "y", "z", *(f"scalar_{name}" for name in SCALARS)),
        "face": ("vertex_indices",),
    }
    ply = read_ply(path, need)
    v, triangles = ply["vertex"], ply["face"]["vertex_indices"]
    if triangles.shape[1:] != (3,) and len(triangles):
        raise InputError(f"{path}: faces of {triangles.shape[1]} vertices, not triangles")
    out: dict[str, NDArray[Any]] = {
        "vertices": np.stack([v["x"], v["y"], v["z"]], axis=-1),
        "triangles": triangles.reshape(-1, 3),
    }
    for name in SCALARS:
        out[name] = np.asarray(v[f"scalar_{name}"])
    return out


def write_model_glb(
    path: Path,
    vertices: FloatArray,
    triangles: NDArray[np.int64],
    normals: FloatArray,
    rgb: NDArray[np.uint8],
    temp_c: FloatArray,
    scale: dict[str, Any],
) -> Path:
    """The mesh as GLB (module docstring) with its temperatures (V,) C; ``scale`` (the colour
    scale) in the extras."""
    try:
        import trimesh
    except ImportError:
        raise InputError(
            "writing model.glb needs trimesh: pip install 'thermodepth[map]'"
        ) from None
    mesh = trimesh.Trimesh(
        vertices=vertices,
        faces=triangles,
        vertex_normals=normals,
        vertex_colors=np.column_stack([rgb, np.full(len(rgb), 255, np.uint8)]),
        process=False,
    )
    mesh.vertex_attributes["_TEMPERATURE"] = np.asarray(temp_c, np.float32)
    scene = trimesh.Scene(mesh)
    scene.metadata["temperature_scale"] = scale  # trimesh writes the metadata as extras
    path.write_bytes(scene.export(file_type="glb", include_normals=True))
    return path
