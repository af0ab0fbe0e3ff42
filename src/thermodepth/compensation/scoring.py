"""Scores of compensated readings against their reference temperatures: the paper's Table 6
figure (the error of the mean, in %) and the stricter ones it omits (RMSE, max |error|, SD),
per target and distance, overall, and in the layout of its Tables 1-5 (per VOx bin)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..sweep import SweepTable
from .base import CompensationModel, FloatArray, apply_to_table, flag_names


@dataclass(frozen=True)
class DistanceScore:
    """The paper's Table 6 figure and the stricter ones for readings at one distance of one
    target: n, mean compensated (C), |error of the mean| in % of the reference in C (NaN for
    a 0 C reference, where it has no meaning), RMSE, max |error| and SD (C)."""

    distance_m: float
    reference_temp_c: float
    n: int
    mean_c: float
    error_of_mean_pct: float
    rmse_c: float
    max_abs_error_c: float
    sd_c: float


def _groups(
    compensated_c: FloatArray, table: SweepTable
) -> Iterator[tuple[float, float, NDArray[np.bool_]]]:
    """(reference temperature, distance, rows) of every group of ``table`` with a finite
    compensated reading, by reference then distance (a placement's median distance:
    :meth:`~thermodepth.sweep.SweepTable.distance_groups`)."""
    ref = table["reference_temp_c"]
    groups, centres = table.distance_groups()
    finite = np.isfinite(compensated_c)
    for r in np.unique(ref):
        for g, dist in enumerate(centres):
            sel = (ref == r) & (groups == g) & finite
            if sel.any():
                yield float(r), float(dist), sel


def score(compensated_c: FloatArray, table: SweepTable) -> list[DistanceScore]:
    """Scores per (reference temperature, distance) of compensated readings of ``table``."""
    out = []
    for r, dist, sel in _groups(compensated_c, table):
        v = compensated_c[sel]
        e = v - r
        out.append(
            DistanceScore(
                dist,
                r,
                int(v.size),
                float(v.mean()),
                float(abs(v.mean() - r) / abs(r) * 100) if r != 0 else float("nan"),
                float(np.sqrt(np.mean(e**2))),
                float(np.abs(e).max()),
                float(v.std(ddof=1)) if v.size > 1 else 0.0,
            )
        )
    return out


def overall(compensated_c: FloatArray, table: SweepTable) -> dict[str, float]:
    """RMSE, max |error| and mean error (C) over every finite row."""
    e = compensated_c - table["reference_temp_c"]
    e = e[np.isfinite(e)]
    if e.size == 0:
        nan = float("nan")
        return {"n": 0, "rmse_c": nan, "max_abs_error_c": nan, "mean_error_c": nan}
    return {
        "n": int(e.size),
        "rmse_c": float(np.sqrt(np.mean(e**2))),
        "max_abs_error_c": float(np.abs(e).max()),
        "mean_error_c": float(e.mean()),
    }


def by_vox(
    compensated_c: FloatArray, table: SweepTable, step_c: float = 1.0
) -> dict[tuple[float, float], dict[float, float]]:
    """Mean compensated temperature per (reference, distance) and VOx bin of ``step_c``: the
    layout of the paper's Tables 1-5."""
    out: dict[tuple[float, float], dict[float, float]] = {}
    vox_bin = np.round(table["vox_temp_c"] / step_c) * step_c
    for r, dist, sel in _groups(compensated_c, table):
        out[(r, dist)] = {
            float(b): float(compensated_c[sel][vox_bin[sel] == b].mean())
            for b in np.unique(vox_bin[sel])
        }
    return out


def evaluation_report(
    model: CompensationModel, table: SweepTable, by_vox_step_c: float | None = None
) -> dict[str, Any]:
    """Everything ``thermodepth evaluate`` prints: per target and distance the paper's Table 6
    figure (mean, error of the mean in %) and the stricter ones (RMSE, max |error|, SD),
    overall figures, flag counts and, optionally, the Tables 1-5 layout (mean per VOx bin)."""
    comp = apply_to_table(model, table)
    flags = flag_names(comp.flag)
    if not np.isfinite(comp.temp_c).any():
        counts = ", ".join(f"{flags.count(f)} {f}" for f in sorted(set(flags)))
        raise InputError(f"{table.source}: no reading could be compensated ({counts})")
    report: dict[str, Any] = {
        "method": model.method,
        "test": table.source,
        "per_distance": [s.__dict__ for s in score(comp.temp_c, table)],
        "overall": overall(comp.temp_c, table),
        "flags": {name: flags.count(name) for name in sorted(set(flags))},
    }
    if by_vox_step_c:
        report["by_vox"] = [
            {
                "reference_temp_c": r,
                "distance_m": d,
                "mean_c_by_vox": {f"{k:g}": v for k, v in b.items()},
            }
            for (r, d), b in by_vox(comp.temp_c, table, by_vox_step_c).items()
        ]
    return report
