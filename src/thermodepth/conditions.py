"""Viewing conditions: what lies between an object and the camera besides the distance.

One value, :class:`Conditions`, in the units people give them (Celsius, percent), with one
set of names used everywhere: the settings file's ``radiometry`` section, compensation model
files, sweep CSV columns, command-line options and the Python API. It is checked once, here
(:func:`condition_problem`), and turns into the radiometry's SI
:class:`~thermodepth.radiometry.ObjectParams` at a given distance
(:meth:`Conditions.object_params`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Annotated, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import AfterValidator

from .errors import FieldError
from .frame_radiometry import frame_celsius
from .radiometry import (
    MAX_DISTANCE_M,
    PAPER_2022,
    RADIOMETRY_METHODS,
    RAW_COUNTS,
    TEMP_LIMITS_C,
    ObjectParams,
    PlanckConstants,
    RadiometryParams,
    ThermalOutput,
    celsius_to_kelvin,
    celsius_to_raw,
    raw_to_celsius,
)
from .schema import StrictSchema

FloatArray = NDArray[np.float64]
Value = float | FloatArray

# field: (low, high, low end open, how the range reads in messages)
_LIMITS: dict[str, tuple[float, float, bool, str]] = {
    "emissivity": (0.0, 1.0, True, "0 < emissivity <= 1"),
    "humidity_pct": (0.0, 100.0, False, "0-100 %"),
    "window_transmission": (0.0, 1.0, True, "0 < transmission <= 1"),
    "distance_m": (0.0, MAX_DISTANCE_M, False, f"0-{MAX_DISTANCE_M:g} m"),
}
_TEMPERATURE = (*TEMP_LIMITS_C, True, f"{TEMP_LIMITS_C[0]:g} < T <= {TEMP_LIMITS_C[1]:g} C")


def _limits(name: str) -> tuple[float, float, bool, str] | None:
    return _TEMPERATURE if name.endswith("_temp_c") else _LIMITS.get(name)


def condition_problem(name: str, value: ArrayLike) -> str | None:
    """Why ``value`` (a number or an array of them) cannot be the condition ``name``, or None
    when it can: temperatures (``*_temp_c``) above absolute zero and up to 5000 C, emissivity
    and window transmission in (0, 1], humidity 0-100 %, a distance 0-1000 m. The one check
    of these ranges, wherever a value comes from (options, settings, files, CSV cells)."""
    limits = _limits(name)
    if limits is None:
        return None
    lo, hi, lo_open, text = limits
    v = np.asarray(value, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        bad = ~((v > lo) if lo_open else (v >= lo)) | ~(v <= hi)  # NaN is bad too
    if not bad.any():
        return None
    if v.ndim == 0:
        return f"{float(v):g} is outside {text}"
    return f"{float(v[bad].ravel()[0]):g} (of {v.size} values) is outside {text}"


def check_condition(name: str, value: ArrayLike) -> None:
    """Raise :class:`~thermodepth.errors.FieldError` naming ``name`` when
    :func:`condition_problem` finds one."""
    why = condition_problem(name, value)
    if why:
        raise FieldError(name, why)


def _value(a: ArrayLike) -> Value:
    """Plain floats stay floats; anything else becomes a float64 array."""
    arr = np.asarray(a, dtype=np.float64)
    return float(arr) if arr.ndim == 0 else arr


@dataclass(frozen=True, eq=False)
class Conditions:
    """The viewing conditions of an object, as people give them.

    emissivity: the object's, in (0, 1]; ambient_temp_c: the air's temperature, C;
    reflected_temp_c: the apparent temperature of the surroundings the object reflects, C
    (None: the air's); humidity_pct: relative humidity, %; window_transmission: an external
    window's, in (0, 1] (1: none); window_temp_c: its temperature, C (None: the air's).

    Each may be a number or an array that broadcasts with the counts (a per-pixel emissivity
    map, one value per table row). Checked on construction (:func:`condition_problem`): a bad
    value raises :class:`~thermodepth.errors.FieldError` naming the field.
    """

    emissivity: Value = 0.95
    ambient_temp_c: Value = 25.0
    reflected_temp_c: Value | None = None
    humidity_pct: Value = 50.0
    window_transmission: float = 1.0
    window_temp_c: float | None = None

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None:
                check_condition(f.name, value)
                object.__setattr__(self, f.name, _value(value))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Conditions):
            return NotImplemented
        return all(
            np.array_equal(getattr(self, f.name), getattr(other, f.name)) for f in fields(self)
        )

    __hash__ = None  # type: ignore[assignment]  # arrays: not hashable

    def replace(self, **changes: ArrayLike | None) -> Conditions:
        """A copy with some fields replaced (checked again)."""
        return replace(self, **changes)  # type: ignore[arg-type]

    def object_params(self, distance_m: ArrayLike = 0.0) -> ObjectParams:
        """The radiometry's SI parameters (kelvin, humidity as a fraction) at ``distance_m``
        (metres; a number or a per-pixel map)."""
        air_k = celsius_to_kelvin(self.ambient_temp_c)

        def kelvin_or_air(temp_c: Value | None) -> Value:
            return _value(air_k if temp_c is None else celsius_to_kelvin(temp_c))

        return ObjectParams(
            emissivity=self.emissivity,
            distance_m=_value(distance_m),
            reflected_temp_k=kelvin_or_air(self.reflected_temp_c),
            atmosphere_temp_k=_value(air_k),
            relative_humidity=_value(np.asarray(self.humidity_pct) / 100.0),
            window_transmission=self.window_transmission,
            window_temp_k=kelvin_or_air(self.window_temp_c),
        )

    def as_dict(self) -> dict[str, Any]:
        """The fields of a scalar value as a file holds them (unset ones left out)."""
        out = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None:
                if np.ndim(value):
                    raise ValueError(f"{f.name}: a file holds one value, not an array")
                out[f.name] = float(value)
        return out


@dataclass(frozen=True, eq=False)
class Radiometry:
    """How a camera's pixel values become temperatures: what they are (``output``: raw
    counts, or the camera's own kelvin; :class:`~thermodepth.radiometry.ThermalOutput`), its
    Planck constants (the RBFO model, paper eqs 17-19), the radiometric model (a key of
    :data:`~thermodepth.radiometry.RADIOMETRY_METHODS`) and the viewing conditions.
    An unknown method raises :class:`~thermodepth.errors.FieldError` (``method``)."""

    conditions: Conditions = field(default_factory=Conditions)
    planck: PlanckConstants = PAPER_2022
    method: str = "flir"
    output: ThermalOutput = RAW_COUNTS

    def __post_init__(self) -> None:
        if self.method not in RADIOMETRY_METHODS:
            raise FieldError(
                "method", f"unknown {self.method!r}; choose from {sorted(RADIOMETRY_METHODS)}"
            )

    def params(self, distance_m: ArrayLike = 0.0) -> RadiometryParams:
        """The radiometry's parameters at ``distance_m`` (metres, a number or a map); no limit
        on the signal (:meth:`signal` has made invalid values NaN)."""
        obj = self.conditions.object_params(distance_m)
        return RadiometryParams(planck=self.planck, obj=obj, max_counts=None)

    def signal(self, values: ArrayLike) -> FloatArray:
        """The signal (float counts of the RBFO form) of pixel values, NaN where they are
        invalid (:meth:`~thermodepth.radiometry.ThermalOutput.signal`)."""
        return self.output.signal(values, self.planck)

    def celsius(self, values: ArrayLike, distance_m: ArrayLike = 0.0) -> FloatArray:
        """Object temperature (C) of pixel values seen from ``distance_m`` (NaN where the
        values are invalid: :meth:`invalid`)."""
        return raw_to_celsius(self.signal(values), self.params(distance_m), self.method)

    def counts(self, temp_c: ArrayLike, distance_m: ArrayLike = 0.0) -> FloatArray:
        """Pixel values (float: counts, or the camera's kelvin units) of an object at
        ``temp_c`` seen from ``distance_m``: the inverse of :meth:`celsius`."""
        signal = celsius_to_raw(temp_c, self.params(distance_m), self.method)
        return self.output.values(signal, self.planck)

    def invalid(self, values: ArrayLike) -> NDArray[np.bool_]:
        """Values no temperature can come from (NaN; counts outside the ADC's range; a kelvin
        reading that is no temperature)."""
        return self.output.invalid(values)

    def frame(
        self,
        values: ArrayLike,
        distance_m: ArrayLike,
        gain: float = 1.0,
        offset: float = 0.0,
        limits: tuple[float, float, float, float] = (-np.inf, np.inf, -np.inf, np.inf),
        flag_bits: tuple[int, int, int, int] = (0, 0, 0, 0),
    ) -> tuple[FloatArray, NDArray[np.uint8]] | None:
        """Temperature (C) and flags of a whole uint16 frame at per-pixel distances in one
        pass (:func:`~thermodepth.frame_radiometry.frame_celsius`: the sensor's ``gain`` and
        ``offset`` taken out, pixels beyond ``limits`` flagged with ``flag_bits``), or None
        when it does not apply (another method, a condition map, values not a uint16 frame):
        the caller then takes the numpy path, which gives the same temperatures."""
        if self.method != "flir":
            return None
        return frame_celsius(
            np.asarray(values),
            np.asarray(distance_m),
            self.params(),
            self.output,
            gain,
            offset,
            limits,
            flag_bits,
        )

    def with_output(self, output: ThermalOutput) -> Radiometry:
        """The same radiometry for pixel values of another kind."""
        return self if output == self.output else replace(self, output=output)


def checked_condition(name: str) -> AfterValidator:
    """A pydantic check of one condition field (:func:`condition_problem`)."""

    def check(value: float | None) -> float | None:
        if value is not None and condition_problem(name, value):
            raise ValueError(f"outside {_limits(name)[3]}")  # type: ignore[index]
        return value

    return AfterValidator(check)


class ConditionsSchema(StrictSchema):
    """:class:`Conditions` as a file or a settings section holds them (same names)."""

    emissivity: Annotated[float, checked_condition("emissivity")] = 0.95
    ambient_temp_c: Annotated[float, checked_condition("ambient_temp_c")] = 25.0
    reflected_temp_c: Annotated[float | None, checked_condition("reflected_temp_c")] = None
    humidity_pct: Annotated[float, checked_condition("humidity_pct")] = 50.0
    window_transmission: Annotated[float, checked_condition("window_transmission")] = 1.0
    window_temp_c: Annotated[float | None, checked_condition("window_temp_c")] = None

    def conditions(self) -> Conditions:
        fields_ = {k: getattr(self, k) for k in ConditionsSchema.model_fields}
        return Conditions(**fields_)
