"""The 3D thermal model: the fused surface mesh with a temperature on every vertex, and the
hotspots located on it.

A hotspot is a connected part of the surface (vertices joined by the mesh's edges) whose
fused temperature is at or above a threshold: its peak (the hottest vertex, its position and
temperature), its centre (the area-weighted mean of its vertices), its area (each vertex owns
a third of the area of its triangles) and its extent (the diagonal of its bounding box).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .fusion import SurfaceTemperature

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ThermalModel:
    """vertices (V, 3) and normals (V, 3) in the world (m), triangles (F, 3), the surface's
    temperature per vertex, the voxel size it was fused at (m)."""

    vertices: FloatArray
    triangles: NDArray[np.int64]
    normals: FloatArray
    surface: SurfaceTemperature
    voxel_m: float

    @property
    def temp_c(self) -> FloatArray:
        return self.surface.temp_c

    def vertex_area_m2(self) -> FloatArray:
        """Each vertex's share of the surface (V,): a third of its triangles' areas, m^2."""
        v, f = self.vertices, self.triangles
        area = 0.5 * np.linalg.norm(
            np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1
        )
        out = np.zeros(len(v))
        for k in range(3):
            np.add.at(out, f[:, k], area / 3.0)
        return out

    def area_m2(self) -> float:
        return float(self.vertex_area_m2().sum())

    def hotspots(self, threshold_c: float, min_area_m2: float = 0.0) -> list[Hotspot3D]:
        """The parts of the surface at or above ``threshold_c``, hottest first (module
        docstring); parts smaller than ``min_area_m2`` are left out."""
        hot = np.nan_to_num(self.temp_c, nan=-np.inf) >= threshold_c
        if not hot.any():
            return []
        f = self.triangles
        edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        edges = edges[hot[edges[:, 0]] & hot[edges[:, 1]]]
        n = len(self.vertices)
        graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
        _, labels = connected_components(graph, directed=False)
        area = self.vertex_area_m2()
        found = []
        for label in np.unique(labels[hot]):
            idx = np.flatnonzero(hot & (labels == label))
            a = area[idx]
            if a.sum() < min_area_m2 or len(idx) < 3:
                continue
            peak = idx[np.argmax(self.temp_c[idx])]
            pts = self.vertices[idx]
            normal = (self.normals[idx] * a[:, None]).sum(0)
            found.append(
                Hotspot3D(
                    peak_c=float(self.temp_c[peak]),
                    fused_peak_c=float(self.temp_c[peak]),
                    peak_views=0,
                    peak_m=self.vertices[peak].copy(),
                    centre_m=(pts * a[:, None]).sum(0) / max(a.sum(), 1e-12),
                    normal=normal / max(float(np.linalg.norm(normal)), 1e-12),
                    area_m2=float(a.sum()),
                    extent_m=float(np.linalg.norm(np.ptp(pts, axis=0))),
                    mean_c=float(np.average(self.temp_c[idx], weights=np.maximum(a, 1e-12))),
                    indices=idx,
                )
            )
        return sorted(found, key=lambda h: -h.peak_c)


@dataclass(frozen=True, eq=False)
class Hotspot3D:
    """A hotspot on the model: peak_c (its peak temperature as the views that resolve it best
    read it, :func:`~thermodepth.mapping.fusion.view_peak`, from ``peak_views`` views; the
    hottest vertex's fused temperature, ``fused_peak_c``, until then), peak_m (the hottest
    vertex), centre_m (area-weighted centre, world m), normal (area-weighted, unit), area_m2,
    extent_m (bounding-box diagonal), mean_c (area-weighted), indices (its vertices)."""

    peak_c: float
    fused_peak_c: float
    peak_views: int
    peak_m: FloatArray
    centre_m: FloatArray
    normal: FloatArray
    area_m2: float
    extent_m: float
    mean_c: float
    indices: NDArray[np.intp]

    def as_dict(self) -> dict[str, Any]:
        return {
            "peak_c": round(self.peak_c, 3),
            "peak_views": self.peak_views,
            "fused_peak_c": round(self.fused_peak_c, 3),
            "peak_m": [round(float(x), 4) for x in self.peak_m],
            "centre_m": [round(float(x), 4) for x in self.centre_m],
            "area_cm2": round(self.area_m2 * 1e4, 2),
            "extent_m": round(self.extent_m, 4),
            "mean_c": round(self.mean_c, 3),
            "vertices": len(self.indices),
        }
