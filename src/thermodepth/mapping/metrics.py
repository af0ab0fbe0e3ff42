"""A thermal model measured against the ground truth of a simulated walk.

The model lives in its trajectory's world (depth odometry's: the first frame's camera); it is
first moved into the truth's world by the rigid motion that best fits its poses to the true
ones (:func:`world_alignment`: the ATE's fit of positions alone leaves a short, nearly
straight walk free to turn about its line, which at 2 m moves the model by centimetres).
Then:

- trajectory: ATE (RMSE of the aligned positions, m);
- geometry: accuracy (each vertex's distance to the true surface), completeness (each true
  surface point the walk's depth frames saw: its distance to the nearest vertex), Chamfer
  distance (their mean), precision, recall and F-score at ``near_m`` (Knapitsch et al.,
  Tanks and Temples, 2017);
- coverage: the share of true surface points seen by the thermal camera (in one of the
  truth's counted frames; ``coverage_seen_3``: in three) that have a vertex with a
  temperature within ``near_m`` (the truth counts what each camera saw within the
  depth a map fuses by default, 3 m);
- temperature: on vertices within ``near_m`` of a true surface whose emissivity is the one
  the map was made with (others cannot read true with one emissivity), with 3 trusted views
  or more: the error of the fused temperature and of the baseline (plain averaging) against
  the surface's temperature: MAE, p95 of the absolute error, and both again beyond the
  camera's own bias (the median error, which no fusion can remove);
- hotspots: for each true hotspot at or above the map's threshold (a hot part's bounds),
  the model's hotspot whose centre or peak is nearest to it (found within 5 cm):
  the distance of its centre from the part's bounds and from their centre, and its peak's
  error.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from ..camera import RigidTransform
from ..radiometry import ZERO_C_IN_K
from ..trajectory import Trajectory, absolute_trajectory_error, rigid_alignment
from .model import Hotspot3D, ThermalModel

FloatArray = NDArray[np.float64]


class TrueHotspot(Protocol):
    """A hot part of a simulated scene: its axis-aligned bounds (centre, size, world m)."""

    name: str
    center_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    temp_c: float


class Truth(Protocol):
    """What a simulated walk knows (:class:`~thermodepth.sim.walk_truth.WalkTruth`)."""

    trajectory: Trajectory
    emissivity: FloatArray
    seen_depth: NDArray[np.int32]
    seen_thermal: NDArray[np.int32]

    @property
    def hotspots(self) -> tuple[TrueHotspot, ...]: ...

    def nearest(self, points_m: FloatArray) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]: ...

    def seen_samples(self) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]: ...


def _errors(err: FloatArray) -> dict[str, float]:
    """MAE and p95 of |err|, the bias (median) and both beyond it, C."""
    if not err.size:
        return {}
    bias = float(np.median(err))
    return {
        "mae_c": round(float(np.mean(np.abs(err))), 3),
        "p95_c": round(float(np.percentile(np.abs(err), 95)), 3),
        "bias_c": round(bias, 3),
        "mae_beyond_bias_c": round(float(np.mean(np.abs(err - bias))), 3),
        "p95_beyond_bias_c": round(float(np.percentile(np.abs(err - bias), 95)), 3),
    }


def measure_map(
    model: ThermalModel,
    hotspots: list[Hotspot3D],
    trajectory: Trajectory,
    truth: Truth,
    emissivity: float,
    hotspot_c: float,
    near_m: float = 0.02,
    min_views: int = 3,
) -> dict[str, Any]:
    """The model against the truth (module docstring), as plain data."""
    ate = absolute_trajectory_error(trajectory, truth.trajectory)
    del ate["truth_from_estimate"]
    align = world_alignment(trajectory, truth.trajectory)
    verts = align.apply(model.vertices)
    dist, temp_k, rect = truth.nearest(verts)
    tree = cKDTree(verts)
    samples = truth.seen_samples()[0]
    seen = truth.seen_depth >= 1
    d_truth, _ = tree.query(samples[seen], distance_upper_bound=1.0)
    d_truth = np.minimum(d_truth, 1.0)
    precision = float(np.mean(dist < near_m))
    recall = float(np.mean(d_truth < near_m))
    s = model.surface
    has_temp = np.isfinite(s.temp_c)
    covered = {}
    for views in (1, 3):  # the truth counts every seen_step-th frame
        thermal_seen = truth.seen_thermal >= views
        share = 0.0
        if has_temp.any() and thermal_seen.any():
            d_cov, _ = cKDTree(verts[has_temp]).query(
                samples[thermal_seen], distance_upper_bound=near_m
            )
            share = float(np.mean(np.isfinite(d_cov)))
        covered[views] = round(share, 4)
    same_emissivity = np.abs(truth.emissivity[rect] - emissivity) <= 0.03
    judged = (dist < near_m) & same_emissivity & (s.views >= min_views) & has_temp
    true_c = temp_k - ZERO_C_IN_K
    out: dict[str, Any] = {
        "trajectory": {k: round(float(v), 4) for k, v in ate.items()},
        "geometry": {
            "accuracy_m": round(float(np.mean(dist)), 4),
            "completeness_m": round(float(np.mean(d_truth)), 4),
            "chamfer_m": round(float((np.mean(dist) + np.mean(d_truth)) / 2), 4),
            "precision": round(precision, 4),
            "recall": round(recall, 4),
            "f_score": round(2 * precision * recall / max(precision + recall, 1e-12), 4),
            "at_m": near_m,
        },
        "coverage": covered[1],
        "coverage_seen_3": covered[3],
        "temperature": {
            "vertices": int(judged.sum()),
            "fused": _errors(s.temp_c[judged] - true_c[judged]),
            "plain_average": _errors(s.plain_c[judged] - true_c[judged]),
        },
        "hotspots": _hotspot_errors(
            hotspots, tuple(h for h in truth.hotspots if h.temp_c >= hotspot_c), align, truth
        ),
    }
    fused, plain = out["temperature"]["fused"], out["temperature"]["plain_average"]
    if fused and plain and plain["mae_c"] > 0:
        out["temperature"]["mae_lower_than_plain"] = round(1 - fused["mae_c"] / plain["mae_c"], 4)
    return out


def world_alignment(estimate: Trajectory, truth: Trajectory) -> RigidTransform:
    """The estimate's world into the truth's: the rigid motion (:func:`rigid_alignment`)
    that best fits each estimated pose's position and the points 1 m along its three axes to
    the true pose's at the same time (whole poses, so a straight walk's turn about its line
    is fixed too)."""
    rot_true, pos_true = truth.poses_at(estimate.times_s)
    ends = [np.zeros(3), *np.eye(3)]
    src = np.concatenate([estimate.translations_m + estimate.rotations @ e for e in ends])
    dst = np.concatenate([pos_true + rot_true @ e for e in ends])
    rot, shift = rigid_alignment(src, dst)
    return RigidTransform(rot, shift, "truth", "estimate")


def _hotspot_errors(
    found: list[Hotspot3D], true: tuple[TrueHotspot, ...], align: RigidTransform, truth: Truth
) -> list[dict[str, Any]]:
    """Per true hotspot: the found one nearest to its bounds, the distance of its centre
    from them (0 inside) and from their centre, its peak's error, and the emissivity of the
    surface under its peak (a peak read with another emissivity than its own is off by
    that, not by the map)."""
    rows = []
    centres = align.apply(np.array([f.centre_m for f in found])) if found else np.zeros((0, 3))
    peak_m = align.apply(np.array([f.peak_m for f in found])) if found else np.zeros((0, 3))
    for h in true:
        row: dict[str, Any] = {"name": h.name, "temp_c": h.temp_c, "found": False}
        if found:
            half = np.asarray(h.size_m) / 2

            def to_bounds(p: FloatArray, h: TrueHotspot = h, half: FloatArray = half) -> FloatArray:
                return np.linalg.norm(np.maximum(np.abs(p - h.center_m) - half, 0.0), axis=1)

            # a long part (a pipe) may be found as one hot stretch with its neighbour: its
            # centre then lies off the part, its peak on it
            d = np.minimum(to_bounds(centres), to_bounds(peak_m))
            k = int(np.argmin(d))
            row.update(
                found=bool(d[k] < 0.05),
                distance_m=round(float(to_bounds(centres[k : k + 1])[0]), 4),
                peak_distance_m=round(float(to_bounds(peak_m[k : k + 1])[0]), 4),
                centre_distance_m=round(float(np.linalg.norm(centres[k] - h.center_m)), 4),
                peak_error_c=round(found[k].peak_c - h.temp_c, 3),
                fused_peak_error_c=round(found[k].fused_peak_c - h.temp_c, 3),
                emissivity=round(
                    float(truth.emissivity[truth.nearest(peak_m[k : k + 1])[2][0]]), 3
                ),
            )
        rows.append(row)
    return rows
