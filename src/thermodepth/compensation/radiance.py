"""Our compensation: the sensor's gain and offset in count space, physics for the air path.

In the camera's signal (counts above the offset O, linear in radiance) the measured signal is
W_meas = g(x) W_ap + h(x), where W_ap is what the target sends to the lens through the air
(FLIR's single-pass model: emissivity, reflected surroundings and the transmission
tau(d, RH, T_air)) and g, h are polynomials in the VOx temperature x (the sensor's gain and
offset, degrees chosen by cross-validation). Compensation undoes g and h on the counts and
inverts the radiometry at the true distance, so it carries over to distances and target
temperatures it was not fitted on.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import AfterValidator, Field

from ..conditions import Conditions, ConditionsSchema, Radiometry
from ..errors import FieldError, InputError
from ..radiometry import (
    PAPER_2022,
    PlanckConstants,
    RadiometryParams,
    celsius_to_raw,
    raw_to_celsius,
)
from ..schema import PlanckSchema, StrictSchema
from ..sweep import SweepTable
from .base import (
    Compensated,
    Flag,
    FloatArray,
    Range,
    apply_to_table,
    check_sweep,
    invalid_flag,
    line_of,
    range_flag,
    table_conditions,
)


def _vox_basis(vox_c: ArrayLike, centre_c: float, scale_c: float, degree: int) -> FloatArray:
    """Powers t^0..t^degree of t = (x - centre) / scale, shape (..., degree + 1)."""
    t = (np.asarray(vox_c, np.float64) - centre_c) / scale_c
    return np.stack([t**k for k in range(degree + 1)], axis=-1)


@dataclass(frozen=True)
class RadianceModel:
    """W_meas = g(x) W_ap + h(x) in counts above the offset; g, h polynomials in
    t = (x - vox_centre_c) / vox_scale_c with coefficients ``gain`` and ``offset``.

    planck: the camera's counts calibration; conditions: those of readings that leave them
    out (air temperature, humidity, emissivity); fitted ranges (for flags) of distance, VOx
    (None: fitted on a camera that tells no VOx temperature, g and h then constants) and
    target temperature; cv: the cross-validation that chose the degrees.
    """

    planck: PlanckConstants
    gain: tuple[float, ...]
    offset: tuple[float, ...]
    vox_centre_c: float
    vox_scale_c: float
    conditions: Conditions
    distance_range_m: tuple[float, float]
    vox_range_c: tuple[float, float] | None
    temp_range_c: tuple[float, float]
    cv: dict[str, Any] = field(default_factory=dict)
    method: ClassVar[str] = "radiance"

    # -- the forward model ------------------------------------------------------------------

    def _params(self, distance_m: ArrayLike, conditions: Conditions | None) -> RadiometryParams:
        """Single-pass radiometry with the model's constants and no limit on counts."""
        obj = (conditions or self.conditions).object_params(distance_m)
        return RadiometryParams(planck=self.planck, max_counts=None, obj=obj)

    def gain_offset(self, vox_c: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """g(x) and h(x) (counts) at VOx temperatures ``vox_c`` (C)."""
        g = _vox_basis(vox_c, self.vox_centre_c, self.vox_scale_c, len(self.gain) - 1)
        h = _vox_basis(vox_c, self.vox_centre_c, self.vox_scale_c, len(self.offset) - 1)
        return g @ np.array(self.gain), h @ np.array(self.offset)

    def predict_counts(
        self,
        true_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        conditions: Conditions | None = None,
    ) -> FloatArray:
        """Raw counts the camera gives for a target at ``true_c`` (the forward model)."""
        w_ap = celsius_to_raw(true_c, self._params(distance_m, conditions)) - self.planck.O
        g, h = self.gain_offset(vox_c)
        return self.planck.O + g * w_ap + h

    def predict_measured(
        self,
        true_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        conditions: Conditions | None = None,
    ) -> FloatArray:
        """The uncompensated reading (emissivity, no distance correction) the model predicts
        for a target at ``true_c`` (the curves of Fig. 13)."""
        counts = self.predict_counts(true_c, vox_c, distance_m, conditions)
        return raw_to_celsius(counts, self._params(0.0, conditions))

    # -- compensation -----------------------------------------------------------------------

    def apply_counts(
        self,
        counts: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        conditions: Conditions | None = None,
    ) -> Compensated:
        """True temperature (C) from raw counts: undo the sensor's g(x), h(x), then invert
        emissivity, reflection and air at ``distance_m`` (scalar or per pixel)."""
        s = np.asarray(counts, np.float64)
        g, h = self.gain_offset(vox_c)
        corrected = self.planck.O + (s - self.planck.O - h) / g
        temp = raw_to_celsius(corrected, self._params(distance_m, conditions))
        # each flag at its own shape (often one VOx value and one distance per frame), then
        # broadcast once
        lo, hi = self.temp_range_c
        flag = (
            range_flag(distance_m, *self.distance_range_m, 0.25, Flag.DISTANCE_OUTSIDE)
            | range_flag(temp, lo, hi, max(10.0, 0.5 * (hi - lo)), Flag.TEMPERATURE_OUTSIDE)
            | invalid_flag(temp)
        )
        if self.vox_range_c is not None:
            flag = flag | range_flag(vox_c, *self.vox_range_c, 3.0, Flag.VOX_OUTSIDE)
        return Compensated(temp, np.broadcast_to(flag, temp.shape).astype(np.uint8))

    def apply(
        self,
        measured_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        conditions: Conditions | None = None,
    ) -> Compensated:
        """True temperature (C) from uncompensated readings (radiometry with emissivity but
        no distance correction, as in the sweep CSV). All arguments broadcast."""
        counts = celsius_to_raw(measured_c, self._params(0.0, conditions))
        return self.apply_counts(counts, vox_c, distance_m, conditions)

    def radiometry(
        self, conditions: Conditions, planck: PlanckConstants | None, method: str
    ) -> Radiometry:
        """Its own: the counts model was fitted through single-pass radiometry with these
        Planck constants; another method or other constants are refused."""
        if method != "flir" or (planck is not None and planck != self.planck):
            raise FieldError(
                "radiometry",
                "a radiance compensation model carries its own radiometry (method flir and "
                "the Planck constants it was fitted with); leave radiometry.method and "
                "radiometry.planck out of the settings",
            )
        return Radiometry(conditions, self.planck, "flir")

    def from_counts(
        self, counts: ArrayLike, vox_c: ArrayLike, distance_m: ArrayLike, radiometry: Radiometry
    ) -> Compensated:
        """The values' signal (raw counts as they are, a kelvin output through the model's
        Planck constants), then :meth:`apply_counts`; a whole frame at one VOx temperature
        in one pass (:meth:`~thermodepth.conditions.Radiometry.frame`, the same result)."""
        if np.ndim(vox_c) == 0:
            g, h = self.gain_offset(vox_c)
            (d0, d1), (lo, hi) = self.distance_range_m, self.temp_range_c
            margin = max(10.0, 0.5 * (hi - lo))
            vox_flag = 0
            if self.vox_range_c is not None:
                vox_flag = int(range_flag(vox_c, *self.vox_range_c, 3.0, Flag.VOX_OUTSIDE))
            fast = radiometry.frame(
                counts,
                distance_m,
                float(g),
                float(h),
                (d0 - 0.25, d1 + 0.25, lo - margin, hi + margin),
                (Flag.DISTANCE_OUTSIDE, Flag.TEMPERATURE_OUTSIDE, Flag.INVALID, vox_flag),
            )
            if fast is not None:
                return Compensated(*fast)
        return self.apply_counts(
            radiometry.signal(counts), vox_c, distance_m, radiometry.conditions
        )

    @property
    def vox_reference_c(self) -> float | None:
        return None if self.vox_range_c is None else self.vox_centre_c

    def summary(self) -> list[str]:
        cv = self.cv
        scored = any(v is not None for v in cv.get("rmse_c", {}).values())
        d0, d1 = self.distance_range_m
        if self.vox_range_c is None:
            fitted = (
                f"fitted over {d0:.3g}-{d1:.3g} m without a VOx temperature (the camera tells "
                "none): the sensor's gain and offset are constants; readings beyond are flagged"
            )
        else:
            v0, v1 = self.vox_range_c
            fitted = (
                f"fitted over {d0:.3g}-{d1:.3g} m and VOx {v0:.3g}-{v1:.3g} C; readings beyond "
                "are flagged"
            )
        return [
            f"degrees chosen by cross-validation: {cv.get('degrees')}"
            if scored
            else f"degrees {cv.get('degrees')}: the simplest, as nothing can be held out "
            "(one distance and one target)",
            fitted,
        ] + (
            [
                f"one target temperature ({self.temp_range_c[0]:g} C): the VOx effect is "
                "fitted as the sensor's gain with its offset held at 0; a second target "
                "temperature (20 C or more apart) would fit the offset too and tell them apart"
            ]
            if cv.get("offset_held_at_zero")
            else []
        )

    # -- fitting ----------------------------------------------------------------------------

    @classmethod
    def fit(
        cls,
        table: SweepTable,
        conditions: Conditions | None = None,
        planck: PlanckConstants = PAPER_2022,
        max_degree: int = 3,
        reference_temp_c: float | None = None,
    ) -> RadianceModel:
        """Least squares of g and h over every row; their degrees (0..max_degree) chosen by
        cross-validation (:func:`choose_degrees`). ``conditions``: those of rows that leave
        them out. It fits every target temperature of the sweep: ``reference_temp_c`` (the
        paper's one temperature) is refused."""
        if reference_temp_c is not None:
            raise FieldError(
                "reference_temp_c", "the radiance model fits every target temperature at once"
            )
        conditions = conditions or Conditions()
        check_sweep(table)
        x = table["vox_temp_c"]
        no_vox = np.isnan(x)
        if no_vox.any() and not no_vox.all():
            raise InputError(
                f"{table.source}: {line_of(table, int(np.argmax(no_vox)))}no vox_temp_c, where "
                "other rows have one: fit the readings of one camera at a time"
            )
        if no_vox.all():  # a camera that tells no sensor temperature: g and h constants
            max_degree = 0
        data = _Design.build(table, conditions, planck)
        # one target temperature cannot tell a gain from an offset: the VOx effect is then
        # fitted as a gain with the offset held at 0 (docs/compensation.md says why)
        offset_held = np.unique(table["reference_temp_c"]).size == 1
        candidates = [
            (g, h)
            for g in range(max_degree + 1)
            for h in ([0] if offset_held else range(max_degree + 1))
        ]
        chosen, scores = choose_degrees(data, candidates, offset_held)
        gain, offset = data.solve(*chosen, offset_held)
        ref = table["reference_temp_c"]
        return cls(
            planck,
            tuple(gain),
            tuple(offset),
            data.centre,
            data.scale,
            conditions,
            (float(table["distance_m"].min()), float(table["distance_m"].max())),
            None if no_vox.all() else (float(x.min()), float(x.max())),
            (float(ref.min()), float(ref.max())),
            {
                "degrees": {"gain": chosen[0], "offset": chosen[1]},
                "offset_held_at_zero": offset_held,
                "folds": list(data.folds()),
                # None: not scored (nothing to hold out); the file stays strict JSON
                "rmse_c": {
                    f"{g},{h}": round(s, 5) if np.isfinite(s) else None
                    for (g, h), s in scores.items()
                },
            },
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "planck": PlanckSchema.of(self.planck),
            "gain": list(self.gain),
            "offset": list(self.offset),
            "vox_centre_c": self.vox_centre_c,
            "vox_scale_c": self.vox_scale_c,
            "conditions": self.conditions.as_dict(),
            "distance_range_m": list(self.distance_range_m),
            "vox_range_c": None if self.vox_range_c is None else list(self.vox_range_c),
            "temp_range_c": list(self.temp_range_c),
            "cv": self.cv,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RadianceModel:
        """A model from its file mapping (pydantic's ValidationError when the values cannot
        be a model)."""
        p = RadianceSchema.model_validate(data)
        return cls(
            p.planck.constants(),
            tuple(p.gain),
            tuple(p.offset),
            p.vox_centre_c,
            p.vox_scale_c,
            p.conditions.conditions(),
            (p.distance_range_m[0], p.distance_range_m[1]),
            None if p.vox_range_c is None else (p.vox_range_c[0], p.vox_range_c[1]),
            (p.temp_range_c[0], p.temp_range_c[1]),
            p.cv,
        )


@dataclass(frozen=True, eq=False)
class _Design:
    """A sweep as regression data: W_meas = sum g_k t^k W_ap + sum h_j t^j, weighted so that
    residuals count in kelvin (1 / (dS/dT)^2) and by ``n``."""

    w_meas: FloatArray
    w_ap: FloatArray
    weight: FloatArray
    centre: float
    scale: float
    table: SweepTable
    conditions: Conditions
    planck: PlanckConstants

    @classmethod
    def build(cls, table: SweepTable, cond: Conditions, planck: PlanckConstants) -> _Design:
        rows = table_conditions(table, cond)
        at0 = RadiometryParams(planck=planck, obj=rows.object_params(0.0), max_counts=None)
        meas = table["measured_temp_c"]
        w_meas = celsius_to_raw(meas, at0) - planck.O
        slope = (celsius_to_raw(meas + 0.05, at0) - celsius_to_raw(meas - 0.05, at0)) / 0.1
        atd = at0.with_object(distance_m=table["distance_m"])
        w_ap = celsius_to_raw(table["reference_temp_c"], atd) - planck.O
        x = table["vox_temp_c"]
        if np.isnan(x).all():  # no VOx temperature: only its zeroth power is used
            centre, scale = 0.0, 1.0
        else:
            centre = float((x.min() + x.max()) / 2)
            scale = float(max((x.max() - x.min()) / 2, 1.0))
        weight = table.get("n", 1.0) / slope**2
        return cls(w_meas, w_ap, weight, centre, scale, table, cond, planck)

    def solve(
        self, g_deg: int, h_deg: int, offset_held: bool, rows: NDArray[np.bool_] | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """Gain and offset coefficients by weighted least squares over ``rows`` (all by
        default); with ``offset_held`` the offset is 0 and only the gain is fitted."""
        sel = slice(None) if rows is None else rows
        vox = self.table["vox_temp_c"][sel]
        design = _vox_basis(vox, self.centre, self.scale, g_deg) * self.w_ap[sel, None]
        if not offset_held:
            design = np.concatenate([design, _vox_basis(vox, self.centre, self.scale, h_deg)], 1)
        sw = np.sqrt(self.weight[sel])
        solved = np.linalg.lstsq(design * sw[:, None], self.w_meas[sel] * sw, rcond=None)[0]
        coef: FloatArray = solved.astype(np.float64)
        if offset_held:
            return coef, np.zeros(1)
        return coef[: g_deg + 1], coef[g_deg + 1 :]

    def folds(self) -> dict[str, NDArray[np.bool_]]:
        """Held-out rows per fold, by name: each distance, and each reference temperature
        when there are several (what the model must generalise over)."""
        reference = self.table["reference_temp_c"]
        groups, centres = self.table.distance_groups()
        out = {f"distance {d:g} m": groups == g for g, d in enumerate(centres)}
        refs = np.unique(reference)
        if refs.size > 1:
            out |= {f"target {r:g} C": reference == r for r in refs}
        return out

    def held_out_errors(self, g_deg: int, h_deg: int, offset_held: bool) -> FloatArray:
        """Compensated minus true temperature of every row when its fold was held out."""
        errs = []
        for test in self.folds().values():
            train = ~test
            if not train.any():
                continue
            gain, offset = self.solve(g_deg, h_deg, offset_held, train)
            model = RadianceModel(
                self.planck,
                tuple(gain),
                tuple(offset),
                self.centre,
                self.scale,
                self.conditions,
                (0.0, 0.0),
                (0.0, 0.0),
                (0.0, 0.0),
            )
            sub = self.table.select(test)
            got = apply_to_table(model, sub).temp_c
            errs.append(got - sub["reference_temp_c"])
        return np.concatenate(errs) if errs else np.zeros(0)


def choose_degrees(
    data: _Design, candidates: list[tuple[int, int]], offset_held: bool
) -> tuple[tuple[int, int], dict[tuple[int, int], float]]:
    """Cross-validated RMSE (C) of each (gain degree, offset degree); the simplest candidate
    within 5 % of the best RMSE wins (fewer parameters generalise more safely)."""
    scores = {}
    for g, h in candidates:
        err = data.held_out_errors(g, h, offset_held)
        scores[(g, h)] = float(np.sqrt(np.nanmean(err**2))) if err.size else float("nan")
    finite = {k: v for k, v in scores.items() if np.isfinite(v)}
    if not finite:  # a single fold: nothing to hold out, take the simplest
        return min(candidates, key=sum), scores
    best = min(finite.values())
    ok = [k for k, v in finite.items() if v <= best * 1.05]
    return min(ok, key=lambda k: (sum(k), finite[k])), scores


def _positive_first(gain: list[float]) -> list[float]:
    if not gain[0] > 0:
        raise ValueError("the gain at the VOx centre (the first) must be > 0")
    return gain


class RadianceSchema(StrictSchema):
    planck: PlanckSchema
    # the sensor's gain at the VOx centre: a factor near 1, never 0 (compensation divides by it)
    gain: Annotated[list[float], Field(min_length=1), AfterValidator(_positive_first)]
    offset: list[float] = Field(min_length=1)
    vox_centre_c: float
    vox_scale_c: float = Field(gt=0)
    conditions: ConditionsSchema
    distance_range_m: Range
    vox_range_c: Range | None = None
    temp_range_c: Range
    cv: dict[str, Any] = Field(default_factory=dict)
