"""The paper's compensation (Lin & Yao 2022, section 4, eq. 20).

For each calibrated distance d, a least-squares line y_d(x) = a_d ln(x) + b_d of the measured
temperature against the VOx temperature x (Celsius, as the paper) at one reference
temperature T_ref; compensated = measured + (T_ref - y_d(x)). Between distances the
correction is interpolated linearly; outside the calibrated distances it is clamped and
flagged. The published coefficients are the preset ``paper2022``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike
from pydantic import AfterValidator, Field

from ..conditions import Conditions, Radiometry
from ..errors import InputError
from ..radiometry import PAPER_2022, PlanckConstants
from ..schema import StrictSchema
from ..sweep import SweepTable
from .base import (
    Compensated,
    Flag,
    FloatArray,
    Range,
    check_sweep,
    invalid_flag,
    line_of,
    range_flag,
)


@dataclass(frozen=True)
class PaperModel:
    """y_d(x) = a_d ln(x) + b_d per calibrated distance (x: VOx temperature in C), fitted at
    ``reference_temp_c``; compensated = measured + (reference - y_d(x))."""

    distances_m: tuple[float, ...]
    a: tuple[float, ...]
    b: tuple[float, ...]
    reference_temp_c: float
    vox_range_c: tuple[float, float]
    note: str = ""
    method: ClassVar[str] = "paper"
    #: its correction is in Celsius: the conditions of readings do not enter it
    conditions: ClassVar[Conditions] = Conditions()

    @classmethod
    def fit(
        cls,
        table: SweepTable,
        reference_temp_c: float | None = None,
        conditions: Conditions | None = None,
    ) -> PaperModel:
        """Least squares per distance on the rows at ``reference_temp_c`` (default: 39 C if
        the sweep has it, else its most frequent reference temperature); a measured distance
        that wanders by millimetres is one calibrated distance, its median
        (:meth:`~thermodepth.sweep.SweepTable.distance_groups`). ``conditions`` do not enter:
        the model works on the readings as they are."""
        check_sweep(table)
        ref = _pick_reference(table, reference_temp_c)
        rows = table.select(table["reference_temp_c"] == ref)
        x, y = rows["vox_temp_c"], rows["measured_temp_c"]
        weights = rows.get("n", 1.0)
        if np.isnan(x).any():
            line = line_of(rows, int(np.argmax(np.isnan(x))))
            raise InputError(
                f"{table.source}: {line}no vox_temp_c: the paper's eq. 20 is a line in ln(VOx) "
                "and cannot be fitted on readings of a camera that tells no sensor temperature "
                "(use --method radiance)"
            )
        if np.any(x <= 0):
            line = line_of(rows, int(np.argmax(x <= 0)))
            raise InputError(
                f"{table.source}: {line}vox_temp_c <= 0 C: the paper's model takes ln(x) of the "
                "VOx temperature in Celsius, which needs x > 0 C (use --method radiance)"
            )
        dists, a, b = [], [], []
        groups, centres = rows.distance_groups()
        for g, dist in enumerate(centres):
            sel = groups == g
            distinct = np.unique(np.round(x[sel], 2)).size
            if distinct < 3:
                raise InputError(
                    f"{table.source}: distance {dist:g} m has {distinct} distinct VOx "
                    f"temperature{'s' if distinct != 1 else ''} at {ref:g} C; fitting "
                    "y = a ln(x) + b needs at least 3"
                )
            sw = np.sqrt(weights[sel])
            design = np.stack([np.log(x[sel]), np.ones(sel.sum())], axis=1) * sw[:, None]
            (ad, bd), *_ = np.linalg.lstsq(design, y[sel] * sw, rcond=None)
            dists.append(float(dist))
            a.append(float(ad))
            b.append(float(bd))
        return cls(tuple(dists), tuple(a), tuple(b), float(ref), (float(x.min()), float(x.max())))

    @classmethod
    def preset_2022(cls) -> PaperModel:
        """The published eq. (20) of Lin & Yao 2022 (reference 39 C, VOx 25-40 C)."""
        return cls(
            (0.5, 1.0, 1.5, 2.0, 2.5),
            (5.595, 5.894, 5.343, 5.428, 6.427),
            (19.140, 20.696, 19.281, 20.179, 24.084),
            39.0,
            (25.0, 40.0),
            note="published coefficients (eq. 20). The 2.5 m line gives 44.8-47.8 C over x = "
            "25-40 C while the others give 36-42 C: its offset looks inconsistent; kept "
            "as published.",
        )

    def curve(self, vox_c: ArrayLike, distance_m: float) -> FloatArray:
        """y_d(x), the model's uncompensated reading at a calibrated distance (Fig. 13)."""
        i = self.distances_m.index(distance_m)
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.a[i] * np.log(np.asarray(vox_c, np.float64)) + self.b[i]

    def correction(self, vox_c: ArrayLike, distance_m: ArrayLike) -> Compensated:
        """reference - y_d(x), interpolated linearly between calibrated distances (clamped
        and flagged outside them). Interpolating a and b is the same, and needs one log."""
        x = np.asarray(vox_c, np.float64)
        d = np.asarray(distance_m, np.float64)
        ds = np.array(self.distances_m)
        with np.errstate(divide="ignore", invalid="ignore"):
            ln_x = np.log(x)
            if ln_x.ndim == 0:  # one VOx value for a whole frame: y_d at the nodes, one interp
                y = np.interp(d, ds, np.multiply(self.a, ln_x) + self.b)
            else:  # np.interp clamps beyond the calibrated distances
                y = np.interp(d, ds, self.a) * ln_x + np.interp(d, ds, self.b)
        corr = self.reference_temp_c - y
        # each flag at its own shape (one VOx value, a distance map), broadcast once
        bad = ~np.isfinite(corr) | (x <= 0)
        flag = (
            range_flag(d, ds[0], ds[-1], 1e-9, Flag.DISTANCE_OUTSIDE)
            | range_flag(x, *self.vox_range_c, 0.5, Flag.VOX_OUTSIDE)
            | np.where(bad, np.uint8(Flag.INVALID), np.uint8(0))
        )
        return Compensated(np.where(bad, np.nan, corr), np.broadcast_to(flag, corr.shape).copy())

    def apply(
        self,
        measured_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        conditions: Conditions | None = None,
    ) -> Compensated:
        """Compensated temperature (C) of readings; all arguments broadcast (whole frames with
        a per-pixel distance map work). The conditions are in the readings already."""
        corr, flag = self.correction(vox_c, distance_m)
        m = np.asarray(measured_c, np.float64)
        return Compensated(m + corr, flag | invalid_flag(m))

    def predict_measured(
        self,
        true_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        conditions: Conditions | None = None,
    ) -> FloatArray:
        """true - (reference - y_d(x)): y_d(x) itself for a target at the reference."""
        return np.asarray(true_c, np.float64) - self.correction(vox_c, distance_m).temp_c

    def radiometry(
        self, conditions: Conditions, planck: PlanckConstants | None, method: str
    ) -> Radiometry:
        """Any radiometry: the paper's correction applies to its readings."""
        return Radiometry(conditions, planck or PAPER_2022, method)

    def from_counts(
        self, counts: ArrayLike, vox_c: ArrayLike, distance_m: ArrayLike, radiometry: Radiometry
    ) -> Compensated:
        """The reading of the counts without distance correction (as the paper reads them),
        then eq. 20 at each pixel's distance."""
        return self.apply(radiometry.celsius(counts), vox_c, distance_m)

    @property
    def vox_reference_c(self) -> float | None:
        return 0.5 * (self.vox_range_c[0] + self.vox_range_c[1])

    def summary(self) -> list[str]:
        d = self.distances_m
        return [
            f"eq. 20 lines at {', '.join(f'{x:g}' for x in d)} m, fitted at "
            f"{self.reference_temp_c:g} C over VOx {self.vox_range_c[0]:g}-"
            f"{self.vox_range_c[1]:g} C; readings beyond are flagged",
        ]

    def to_dict(self) -> dict[str, Any]:
        return {
            "distances_m": list(self.distances_m),
            "a": list(self.a),
            "b": list(self.b),
            "reference_temp_c": self.reference_temp_c,
            "vox_range_c": list(self.vox_range_c),
            "note": self.note,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PaperModel:
        """A model from its file mapping (pydantic's ValidationError, or ValueError, when
        the values cannot be a model)."""
        p = PaperSchema.model_validate(data)
        if not (len(p.a) == len(p.b) == len(p.distances_m)):
            raise ValueError("distances_m, a and b must have the same length")
        return cls(
            tuple(p.distances_m),
            tuple(p.a),
            tuple(p.b),
            p.reference_temp_c,
            (p.vox_range_c[0], p.vox_range_c[1]),
            p.note,
        )


def _pick_reference(table: SweepTable, wanted: float | None) -> float:
    refs, counts = np.unique(table["reference_temp_c"], return_counts=True)
    if wanted is None:  # the paper's 39 C, else the most frequent
        wanted = 39.0 if np.any(np.isclose(refs, 39.0)) else float(refs[np.argmax(counts)])
    if not np.any(np.isclose(refs, wanted)):
        raise InputError(
            f"{table.source}: no rows at reference_temp_c = {wanted:g} C "
            f"(found: {', '.join(f'{r:g}' for r in refs)})"
        )
    return float(refs[np.isclose(refs, wanted)][0])  # the table's own value


def _increasing_positive(values: list[float]) -> list[float]:
    if values[0] <= 0 or any(b <= a for a, b in itertools.pairwise(values)):
        raise ValueError("expected distances > 0 in increasing order")
    return values


class PaperSchema(StrictSchema):
    distances_m: Annotated[list[float], Field(min_length=1), AfterValidator(_increasing_positive)]
    a: list[float]
    b: list[float]
    reference_temp_c: float
    vox_range_c: Range
    note: str = ""
