"""Compensation of distance and VOx (sensor) temperature: the paper's method and ours.

A thermal camera's uncompensated reading of a target drifts with the temperature of its own
vanadium-oxide focal plane (the paper's x, "VOx temperature") and falls with distance (air
absorbs). Both models here turn a reading into the target's true temperature given x and
the distance; both are fitted on a sweep (``thermodepth.sweep``) and saved as versioned JSON.

``COMPENSATION_METHODS``:

- ``"paper"`` (Lin & Yao 2022, section 4, eq. 20): for each calibrated distance d, a least-
  squares line y_d(x) = a_d ln(x) + b_d of the measured temperature against x (Celsius, as the
  paper) at one reference temperature T_ref; compensated = measured + (T_ref - y_d(x)). Between
  distances the correction is interpolated linearly; outside the calibrated distances it is
  clamped and flagged. The published coefficients are the preset ``paper2022``.
- ``"radiance"`` (ours): in the camera's signal (counts above the offset O, linear in radiance),
  the measured signal is W_meas = g(x) W_ap + h(x), where W_ap is what the target sends to the
  lens through the air (FLIR's single-pass model: emissivity, reflected surroundings and the
  transmission tau(d, RH, T_air)) and g, h are polynomials in x (gain and offset of the
  sensor, degrees chosen by cross-validation). Compensation undoes g and h on the counts and
  inverts the radiometry at the true distance, so it carries over to distances and target
  temperatures it was not fitted on.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from enum import IntFlag
from pathlib import Path
from typing import Annotated, Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import AfterValidator, Field, ValidationError

from .calibration import (
    PlanckSchema,
    StrictSchema,
    describe_validation_error,
    read_mapping,
    write_mapping,
)
from .errors import InputError
from .radiometry import (
    PAPER_2022,
    ObjectParams,
    PlanckConstants,
    RadiometryParams,
    celsius_to_raw,
    raw_to_celsius,
)
from .sweep import REQUIRED, SweepTable

FloatArray = NDArray[np.float64]
SCHEMA = "thermodepth.compensation"
SCHEMA_VERSION = 1


class Flag(IntFlag):
    """Why a compensated value deserves care (bits, OR-ed per reading)."""

    OK = 0
    DISTANCE_OUTSIDE = 1  # beyond the fitted distances (paper: clamped; ours: extrapolated)
    VOX_OUTSIDE = 2  # VOx temperature beyond the fitted range
    TEMPERATURE_OUTSIDE = 4  # reading beyond the fitted target temperatures
    INVALID = 8  # no value: NaN input, or x <= 0 C for the paper's ln(x)


class Compensated(NamedTuple):
    """Compensated temperatures (C) and their flags (uint8, :class:`Flag` bits)."""

    temp_c: FloatArray
    flag: NDArray[np.uint8]


@dataclass(frozen=True)
class Conditions:
    """Defaults for what a sweep or a reading may leave out: air (and reflected surroundings)
    temperature in C, relative humidity in %, the target's emissivity."""

    ambient_temp_c: float = 25.0
    humidity_pct: float = 50.0
    emissivity: float = 0.95


def _range_flag(
    value: FloatArray, lo: float, hi: float, margin: float, flag: Flag
) -> NDArray[np.uint8]:
    with np.errstate(invalid="ignore"):
        out = (value < lo - margin) | (value > hi + margin)
    return np.where(out, np.uint8(flag), np.uint8(0))


# ---------------------------------------------------------------------------------------------
# The paper's method
# ---------------------------------------------------------------------------------------------


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

    @classmethod
    def fit(cls, table: SweepTable, reference_temp_c: float | None = None) -> PaperModel:
        """Least squares per distance on the rows at ``reference_temp_c`` (default: 39 C if
        the sweep has it, else its most frequent reference temperature)."""
        _check_sweep(table)
        ref = _pick_reference(table, reference_temp_c)
        rows = table.select(table["reference_temp_c"] == ref)
        x, y, d = rows["vox_temp_c"], rows["measured_temp_c"], rows["distance_m"]
        weights = rows.get("n", 1.0)
        if np.any(x <= 0):
            line = _line_of(rows, int(np.argmax(x <= 0)))
            raise InputError(
                f"{table.source}: {line}vox_temp_c <= 0 C: the paper's model takes ln(x) of the "
                "VOx temperature in Celsius, which needs x > 0 C (use --method radiance)"
            )
        dists, a, b = [], [], []
        for dist in np.unique(d):
            sel = d == dist
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
            _range_flag(d, ds[0], ds[-1], 1e-9, Flag.DISTANCE_OUTSIDE)
            | _range_flag(x, *self.vox_range_c, 0.5, Flag.VOX_OUTSIDE)
            | np.where(bad, np.uint8(Flag.INVALID), np.uint8(0))
        )
        return Compensated(np.where(bad, np.nan, corr), np.broadcast_to(flag, corr.shape).copy())

    def apply(
        self,
        measured_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        **_conditions: ArrayLike | None,
    ) -> Compensated:
        """Compensated temperature (C) of readings; all arguments broadcast (whole frames with
        a per-pixel distance map work)."""
        corr, flag = self.correction(vox_c, distance_m)
        m = np.asarray(measured_c, np.float64)
        flag = flag | np.where(np.isfinite(m), np.uint8(0), np.uint8(Flag.INVALID))
        return Compensated(m + corr, flag)

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
        p = _PaperSchema.model_validate(data)
        if not (len(p.a) == len(p.b) == len(p.distances_m)):
            raise ValueError("distances_m, a and b must have the same length")
        if list(p.distances_m) != sorted(set(p.distances_m)):
            raise ValueError("distances_m must increase")
        return cls(
            tuple(p.distances_m),
            tuple(p.a),
            tuple(p.b),
            p.reference_temp_c,
            (p.vox_range_c[0], p.vox_range_c[1]),
            p.note,
        )


# ---------------------------------------------------------------------------------------------
# Our method: sensor gain and offset in count space, physics for the air path
# ---------------------------------------------------------------------------------------------


def _vox_basis(vox_c: FloatArray, centre_c: float, scale_c: float, degree: int) -> FloatArray:
    """Powers t^0..t^degree of t = (x - centre) / scale, shape (..., degree + 1)."""
    t = (np.asarray(vox_c, np.float64) - centre_c) / scale_c
    return np.stack([t**k for k in range(degree + 1)], axis=-1)


@dataclass(frozen=True)
class RadianceModel:
    """W_meas = g(x) W_ap + h(x) in counts above the offset; g, h polynomials in
    t = (x - vox_centre_c) / vox_scale_c with coefficients ``gain`` and ``offset``.

    planck: the camera's counts calibration; conditions: defaults for readings that leave out
    the air temperature, humidity or emissivity; fitted ranges (for flags) of distance, VOx
    and target temperature; cv: the cross-validation that chose the degrees.
    """

    planck: PlanckConstants
    gain: tuple[float, ...]
    offset: tuple[float, ...]
    vox_centre_c: float
    vox_scale_c: float
    conditions: Conditions
    distance_range_m: tuple[float, float]
    vox_range_c: tuple[float, float]
    temp_range_c: tuple[float, float]
    cv: dict[str, Any] = field(default_factory=dict)
    method: ClassVar[str] = "radiance"

    # -- the forward model ------------------------------------------------------------------

    def _params(
        self,
        distance_m: ArrayLike,
        ambient_c: ArrayLike | None,
        humidity_pct: ArrayLike | None,
        emissivity: ArrayLike | None,
        reflected_c: ArrayLike | None,
    ) -> RadiometryParams:
        c = self.conditions
        obj = ObjectParams.from_celsius(
            c.emissivity if emissivity is None else emissivity,
            distance_m,
            c.ambient_temp_c if ambient_c is None else ambient_c,
            c.humidity_pct if humidity_pct is None else humidity_pct,
            reflected_c,
        )
        return RadiometryParams(planck=self.planck, max_counts=None, obj=obj)

    def gain_offset(self, vox_c: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """g(x) and h(x) (counts) at VOx temperatures ``vox_c`` (C)."""
        x = np.asarray(vox_c, np.float64)
        g = _vox_basis(x, self.vox_centre_c, self.vox_scale_c, len(self.gain) - 1) @ np.array(
            self.gain
        )
        h = _vox_basis(x, self.vox_centre_c, self.vox_scale_c, len(self.offset) - 1) @ np.array(
            self.offset
        )
        return g, h

    def predict_counts(
        self,
        true_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        ambient_c: ArrayLike | None = None,
        humidity_pct: ArrayLike | None = None,
        emissivity: ArrayLike | None = None,
        reflected_c: ArrayLike | None = None,
    ) -> FloatArray:
        """Raw counts the camera gives for a target at ``true_c`` (the forward model)."""
        params = self._params(distance_m, ambient_c, humidity_pct, emissivity, reflected_c)
        w_ap = celsius_to_raw(true_c, params) - self.planck.O
        g, h = self.gain_offset(vox_c)
        return self.planck.O + g * w_ap + h

    def predict_measured(
        self,
        true_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        ambient_c: ArrayLike | None = None,
        humidity_pct: ArrayLike | None = None,
        emissivity: ArrayLike | None = None,
        reflected_c: ArrayLike | None = None,
    ) -> FloatArray:
        """The uncompensated reading (emissivity, no distance correction) the model predicts
        for a target at ``true_c`` (the curves of Fig. 13)."""
        counts = self.predict_counts(
            true_c, vox_c, distance_m, ambient_c, humidity_pct, emissivity, reflected_c
        )
        return raw_to_celsius(
            counts, self._params(0.0, ambient_c, humidity_pct, emissivity, reflected_c)
        )

    # -- compensation -----------------------------------------------------------------------

    def apply_counts(
        self,
        counts: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        ambient_c: ArrayLike | None = None,
        humidity_pct: ArrayLike | None = None,
        emissivity: ArrayLike | None = None,
        reflected_c: ArrayLike | None = None,
    ) -> Compensated:
        """True temperature (C) from raw counts: undo the sensor's g(x), h(x), then invert
        emissivity, reflection and air at ``distance_m`` (scalar or per pixel)."""
        s = np.asarray(counts, np.float64)
        g, h = self.gain_offset(vox_c)
        corrected = self.planck.O + (s - self.planck.O - h) / g
        temp = raw_to_celsius(
            corrected, self._params(distance_m, ambient_c, humidity_pct, emissivity, reflected_c)
        )
        # each flag at its own shape (often one VOx value and one distance per frame), then
        # broadcast once
        lo, hi = self.temp_range_c
        flag = (
            _range_flag(
                np.asarray(distance_m, np.float64),
                *self.distance_range_m,
                0.25,
                Flag.DISTANCE_OUTSIDE,
            )
            | _range_flag(np.asarray(vox_c, np.float64), *self.vox_range_c, 3.0, Flag.VOX_OUTSIDE)
            | _range_flag(temp, lo, hi, max(10.0, 0.5 * (hi - lo)), Flag.TEMPERATURE_OUTSIDE)
            | np.where(np.isfinite(temp), np.uint8(0), np.uint8(Flag.INVALID))
        )
        return Compensated(temp, np.broadcast_to(flag, temp.shape).astype(np.uint8))

    def apply(
        self,
        measured_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        ambient_c: ArrayLike | None = None,
        humidity_pct: ArrayLike | None = None,
        emissivity: ArrayLike | None = None,
        reflected_c: ArrayLike | None = None,
    ) -> Compensated:
        """True temperature (C) from uncompensated readings (radiometry with emissivity but
        no distance correction, as in the sweep CSV). All arguments broadcast."""
        counts = celsius_to_raw(
            measured_c, self._params(0.0, ambient_c, humidity_pct, emissivity, reflected_c)
        )
        return self.apply_counts(
            counts, vox_c, distance_m, ambient_c, humidity_pct, emissivity, reflected_c
        )

    # -- fitting ----------------------------------------------------------------------------

    @classmethod
    def fit(
        cls,
        table: SweepTable,
        conditions: Conditions | None = None,
        planck: PlanckConstants = PAPER_2022,
        max_degree: int = 3,
    ) -> RadianceModel:
        """Least squares of g and h over every row; their degrees (0..max_degree) chosen by
        cross-validation (:func:`choose_degrees`)."""
        conditions = conditions or Conditions()
        _check_sweep(table)
        data = _Design.build(table, conditions, planck)
        refs = np.unique(table["reference_temp_c"])
        if refs.size == 1:
            # one target temperature: gain and offset cannot be told apart, fit offset only
            candidates = [(0, k) for k in range(max_degree + 1)]
            fixed_gain = True
        else:
            candidates = [(g, h) for g in range(max_degree + 1) for h in range(max_degree + 1)]
            fixed_gain = False
        chosen, scores = choose_degrees(data, candidates, fixed_gain)
        gain, offset = data.solve(*chosen, fixed_gain)
        x, ref = table["vox_temp_c"], table["reference_temp_c"]
        return cls(
            planck,
            tuple(gain),
            tuple(offset),
            data.centre,
            data.scale,
            conditions,
            (float(table["distance_m"].min()), float(table["distance_m"].max())),
            (float(x.min()), float(x.max())),
            (float(ref.min()), float(ref.max())),
            {
                "degrees": {"gain": chosen[0], "offset": chosen[1]},
                "gain_fixed_to_one": fixed_gain,
                "folds": list(data.folds()),
                # None: not scored (nothing to hold out); the file stays strict JSON
                "rmse_c": {
                    f"{g},{h}": round(s, 5) if np.isfinite(s) else None
                    for (g, h), s in scores.items()
                },
            },
        )

    def to_dict(self) -> dict[str, Any]:
        pl = self.planck
        return {
            "planck": {"R": pl.R, "B": pl.B, "F": pl.F, "O": pl.O},
            "gain": list(self.gain),
            "offset": list(self.offset),
            "vox_centre_c": self.vox_centre_c,
            "vox_scale_c": self.vox_scale_c,
            "conditions": self.conditions.__dict__,
            "distance_range_m": list(self.distance_range_m),
            "vox_range_c": list(self.vox_range_c),
            "temp_range_c": list(self.temp_range_c),
            "cv": self.cv,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RadianceModel:
        p = _RadianceSchema.model_validate(data)
        return cls(
            p.planck.constants(),
            tuple(p.gain),
            tuple(p.offset),
            p.vox_centre_c,
            p.vox_scale_c,
            Conditions(**p.conditions.model_dump()),
            (p.distance_range_m[0], p.distance_range_m[1]),
            (p.vox_range_c[0], p.vox_range_c[1]),
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
        amb = table.get("ambient_temp_c", cond.ambient_temp_c)
        rh = table.get("humidity_pct", cond.humidity_pct)
        eps = table.get("emissivity", cond.emissivity)
        at0 = RadiometryParams(
            planck=planck, obj=ObjectParams.from_celsius(eps, 0.0, amb, rh), max_counts=None
        )
        meas = table["measured_temp_c"]
        w_meas = celsius_to_raw(meas, at0) - planck.O
        slope = (celsius_to_raw(meas + 0.05, at0) - celsius_to_raw(meas - 0.05, at0)) / 0.1
        atd = at0.with_object(distance_m=table["distance_m"])
        w_ap = celsius_to_raw(table["reference_temp_c"], atd) - planck.O
        x = table["vox_temp_c"]
        centre = float((x.min() + x.max()) / 2)
        scale = float(max((x.max() - x.min()) / 2, 1.0))
        weight = table.get("n", 1.0) / slope**2
        return cls(
            w_meas,
            w_ap,
            weight,
            centre,
            scale,
            table,
            cond,
            planck,
        )

    def solve(
        self, g_deg: int, h_deg: int, fixed_gain: bool, rows: NDArray[np.bool_] | None = None
    ) -> tuple[FloatArray, FloatArray]:
        sel = slice(None) if rows is None else rows
        vox = self.table["vox_temp_c"][sel]
        t_g = _vox_basis(vox, self.centre, self.scale, g_deg)
        t_h = _vox_basis(vox, self.centre, self.scale, h_deg)
        target = self.w_meas[sel]
        if fixed_gain:
            target = target - self.w_ap[sel]
            design = t_h
        else:
            design = np.concatenate([t_g * self.w_ap[sel, None], t_h], axis=1)
        sw = np.sqrt(self.weight[sel])
        coef = np.linalg.lstsq(design * sw[:, None], target * sw, rcond=None)[0].astype(np.float64)
        if fixed_gain:
            return np.array([1.0] + [0.0] * g_deg), coef
        return coef[: g_deg + 1], coef[g_deg + 1 :]

    def folds(self) -> dict[str, NDArray[np.bool_]]:
        """Held-out rows per fold, by name: each distance, and each reference temperature
        when there are several (what the model must generalise over)."""
        distance, reference = self.table["distance_m"], self.table["reference_temp_c"]
        out = {f"distance {d:g} m": distance == d for d in np.unique(distance)}
        refs = np.unique(reference)
        if refs.size > 1:
            out |= {f"target {r:g} C": reference == r for r in refs}
        return out

    def held_out_errors(self, g_deg: int, h_deg: int, fixed_gain: bool) -> FloatArray:
        """Compensated minus true temperature of every row when its fold was held out."""
        errs = []
        for test in self.folds().values():
            train = ~test
            if not train.any():
                continue
            gain, offset = self.solve(g_deg, h_deg, fixed_gain, train)
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
    data: _Design, candidates: list[tuple[int, int]], fixed_gain: bool
) -> tuple[tuple[int, int], dict[tuple[int, int], float]]:
    """Cross-validated RMSE (C) of each (gain degree, offset degree); the simplest candidate
    within 5 % of the best RMSE wins (fewer parameters generalise more safely)."""
    scores = {}
    for g, h in candidates:
        err = data.held_out_errors(g, h, fixed_gain)
        scores[(g, h)] = float(np.sqrt(np.nanmean(err**2))) if err.size else float("nan")
    finite = {k: v for k, v in scores.items() if np.isfinite(v)}
    if not finite:  # a single fold: nothing to hold out, take the simplest
        return min(candidates, key=sum), scores
    best = min(finite.values())
    ok = [k for k, v in finite.items() if v <= best * 1.05]
    return min(ok, key=lambda k: (sum(k), finite[k])), scores


# ---------------------------------------------------------------------------------------------
# Applying to tables, evaluation, save/load
# ---------------------------------------------------------------------------------------------

CompensationModel = PaperModel | RadianceModel

COMPENSATION_METHODS: dict[str, Callable[..., CompensationModel]] = {
    "radiance": RadianceModel.fit,
    "paper": PaperModel.fit,
}

PRESETS: dict[str, Callable[[], CompensationModel]] = {"paper2022": PaperModel.preset_2022}


def fit(table: SweepTable, method: str = "radiance", **options: Any) -> CompensationModel:
    """Fit ``method`` (``COMPENSATION_METHODS``) on a sweep."""
    if method not in COMPENSATION_METHODS:
        raise InputError(
            f"--method: unknown {method!r}; choose from {sorted(COMPENSATION_METHODS)}"
        )
    return COMPENSATION_METHODS[method](table, **options)


def apply_to_table(model: CompensationModel, table: SweepTable) -> Compensated:
    """Compensate every row of a readings table (uses its optional condition columns)."""
    given = {
        arg: table[column]
        for arg, column in (
            ("ambient_c", "ambient_temp_c"),
            ("humidity_pct", "humidity_pct"),
            ("emissivity", "emissivity"),
        )
        if column in table
    }
    return model.apply(table["measured_temp_c"], table["vox_temp_c"], table["distance_m"], **given)


def _check_sweep(table: SweepTable) -> None:
    if len(table) == 0:
        raise InputError(f"{table.source}: no rows to fit")
    for name in REQUIRED:
        if name not in table:
            raise InputError(f"{table.source}: missing column {name}")
    if np.any(table["distance_m"] < 0):
        raise InputError(
            f"{table.source}: {_line_of(table, int(np.argmax(table['distance_m'] < 0)))}"
            "distance_m < 0"
        )


def _line_of(table: SweepTable, i: int) -> str:
    return f"line {table.lines[i]}: " if table.lines is not None else ""


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


def _positive_first(gain: list[float]) -> list[float]:
    if not gain[0] > 0:
        raise ValueError("the gain at the VOx centre (the first) must be > 0")
    return gain


def _low_high(pair: list[float]) -> list[float]:
    if pair[0] > pair[1]:
        raise ValueError("expected [low, high]")
    return pair


def _increasing_positive(values: list[float]) -> list[float]:
    if values[0] <= 0 or any(b <= a for a, b in itertools.pairwise(values)):
        raise ValueError("expected distances > 0 in increasing order")
    return values


# a model's range [low, high] (distances, VOx or target temperatures it was fitted over)
_Range = Annotated[list[float], Field(min_length=2, max_length=2), AfterValidator(_low_high)]


class _PaperSchema(StrictSchema):
    distances_m: Annotated[list[float], Field(min_length=1), AfterValidator(_increasing_positive)]
    a: list[float]
    b: list[float]
    reference_temp_c: float
    vox_range_c: _Range
    note: str = ""


class _ConditionsSchema(StrictSchema):
    ambient_temp_c: float
    humidity_pct: float = Field(ge=0, le=100)
    emissivity: float = Field(gt=0, le=1)


class _RadianceSchema(StrictSchema):
    planck: PlanckSchema
    # the sensor's gain at the VOx centre: a factor near 1, never 0 (compensation divides by it)
    gain: Annotated[list[float], Field(min_length=1), AfterValidator(_positive_first)]
    offset: list[float] = Field(min_length=1)
    vox_centre_c: float
    vox_scale_c: float = Field(gt=0)
    conditions: _ConditionsSchema
    distance_range_m: _Range
    vox_range_c: _Range
    temp_range_c: _Range
    cv: dict[str, Any] = Field(default_factory=dict)


_LOADERS: dict[str, Callable[[dict[str, Any]], CompensationModel]] = {
    "paper": PaperModel.from_dict,
    "radiance": RadianceModel.from_dict,
}


def save_model(model: CompensationModel, path: str | Path) -> None:
    """Write a model as a versioned mapping: JSON, or YAML when the name ends otherwise."""
    doc = {
        "schema": SCHEMA,
        "version": SCHEMA_VERSION,
        "method": model.method,
        "model": model.to_dict(),
    }
    write_mapping(path, doc)


def load_model(path: str | Path) -> CompensationModel:
    """Read and validate a model file (JSON or YAML); a bad file raises one InputError line
    naming it."""
    p = Path(path)
    doc = read_mapping(p)
    if doc.get("schema") != SCHEMA:
        raise InputError(f"{p}: not a thermodepth compensation model (schema != {SCHEMA!r})")
    if doc.get("version") != SCHEMA_VERSION:
        raise InputError(
            f"{p}: model version {doc.get('version')!r} is not supported "
            f"(this thermodepth reads version {SCHEMA_VERSION})"
        )
    method = doc.get("method")
    if method not in _LOADERS:
        raise InputError(f"{p}: method: unknown {method!r}; expected one of {sorted(_LOADERS)}")
    try:
        return _LOADERS[method](doc.get("model", {}))
    except ValidationError as exc:
        raise InputError(f"{p}: model.{describe_validation_error(exc)}") from None
    except ValueError as exc:
        raise InputError(f"{p}: model: {exc}") from None


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
    compensated reading, by reference then distance."""
    ref, d = table["reference_temp_c"], table["distance_m"]
    finite = np.isfinite(compensated_c)
    for r in np.unique(ref):
        for dist in np.unique(d[ref == r]):
            sel = (ref == r) & (d == dist) & finite
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


def paper_tables() -> SweepTable:
    """The paper's Tables 1-5 (compensated readings of the 39 C plate), as shipped data."""
    from importlib.resources import files

    text = files("thermodepth").joinpath("data/paper2022_tables.csv").read_text("utf-8")
    rows = [line.split(",") for line in text.splitlines() if line and not line.startswith("#")][1:]
    arr = np.array(rows, dtype=np.float64)
    return SweepTable(
        {
            "distance_m": arr[:, 0],
            "vox_temp_c": arr[:, 1],
            "measured_temp_c": arr[:, 2],
            "reference_temp_c": np.full(len(arr), 39.0),
        },
        source="Lin & Yao 2022, Tables 1-5",
    )


#: Table 6 of Lin & Yao 2022 as published: distance (m) -> (average C, error of the average %).
PAPER_TABLE6: dict[float, tuple[float, float]] = {
    0.5: (38.986, 0.035),
    1.0: (39.039, 0.1),
    1.5: (39.013, 0.033),
    2.0: (39.010, 0.026),
    2.5: (39.022, 0.056),
}


def names_of(value: int, kind: type[IntFlag] = Flag) -> list[str]:
    """Lower-case names of the flags of ``kind`` set in ``value``, lowest bit first."""
    return [m.name.lower() for m in kind(value) if m.name]


def flag_names(flags: ArrayLike) -> list[str]:
    """Readable flags per reading: ``ok`` or names joined by ``|``."""
    return ["|".join(names_of(int(f))) or "ok" for f in np.asarray(flags, dtype=np.uint8).ravel()]


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


def paper_tables_report() -> dict[str, Any]:
    """The paper's Tables 1-5 (shipped data) recomputed into Table 6, beside the published
    Table 6, with the stricter figures the paper does not show."""
    tables = paper_tables()
    return {
        "source": tables.source,
        "published": [
            {"distance_m": d, "average_c": a, "error_pct": e} for d, (a, e) in PAPER_TABLE6.items()
        ],
        "recomputed": [s.__dict__ for s in score(tables["measured_temp_c"], tables)],
        "overall": overall(tables["measured_temp_c"], tables),
    }
