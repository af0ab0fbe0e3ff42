"""What every compensation model is: the protocol the pipeline and the tables call, the flags
a compensated reading carries, and applying a model to a table of readings."""

from __future__ import annotations

from enum import IntFlag
from typing import Annotated, Any, ClassVar, NamedTuple, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import AfterValidator, Field

from ..conditions import Conditions, Radiometry
from ..errors import InputError
from ..radiometry import PlanckConstants
from ..sweep import REQUIRED, SweepTable

FloatArray = NDArray[np.float64]


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


class CompensationModel(Protocol):
    """A compensation of distance and VOx (sensor) temperature.

    Every method implements it (``COMPENSATION_METHODS``); the pipeline and the tables call
    only these, never a model's class. Temperatures in C, distances in metres, VOx in C; all
    arguments broadcast (a whole frame with a per-pixel distance map, or one row per reading).
    """

    method: ClassVar[str]

    @property
    def conditions(self) -> Conditions:
        """The conditions readings are taken under when they leave them out."""
        ...

    @property
    def vox_reference_c(self) -> float | None:
        """The VOx temperature (C) a reading without one is compensated at (a camera that
        does not tell its sensor temperature): the middle of the range the model was fitted
        over; None when the model does not use the VOx temperature."""
        ...

    @property
    def vox_range_c(self) -> tuple[float, float] | None:
        """The VOx temperatures (C, low and high) the model was fitted over; None when it
        does not use the VOx temperature (a monitor's fail-safe watches it)."""
        ...

    def radiometry(
        self, conditions: Conditions, planck: PlanckConstants | None, method: str
    ) -> Radiometry:
        """The radiometry the model works with, given what the settings ask for (``planck``
        None: the model's own, else the paper's constants). Raises
        :class:`~thermodepth.errors.FieldError` when the model cannot work with it."""
        ...

    def from_counts(
        self, counts: ArrayLike, vox_c: ArrayLike, distance_m: ArrayLike, radiometry: Radiometry
    ) -> Compensated:
        """True temperature of a camera's pixel values (the pipeline's path): raw counts, or
        the camera's own temperature, as ``radiometry.output`` says."""
        ...

    def apply(
        self,
        measured_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        conditions: Conditions | None = None,
    ) -> Compensated:
        """True temperature of uncompensated readings (radiometry with emissivity, without
        distance correction: the sweep CSV's ``measured_temp_c``). ``conditions``: those of
        the readings (None: the model's defaults)."""
        ...

    def predict_measured(
        self,
        true_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        conditions: Conditions | None = None,
    ) -> FloatArray:
        """The uncompensated reading the model expects of a target at ``true_c`` (the
        inverse of :meth:`apply`; the curves of the paper's Fig. 13)."""
        ...

    def summary(self) -> list[str]:
        """What the model is, in a few lines for people (what fitting chose, its ranges)."""
        ...

    def to_dict(self) -> dict[str, Any]:
        """The model as a file holds it (``thermodepth.compensation.files``)."""
        ...


def _low_high(pair: list[float]) -> list[float]:
    if pair[0] > pair[1]:
        raise ValueError("expected [low, high]")
    return pair


Range = Annotated[list[float], Field(min_length=2, max_length=2), AfterValidator(_low_high)]
"""A model's range in its file, [low, high] (the distances, VOx or target temperatures it
was fitted over)."""


def range_flag(
    value: ArrayLike, lo: float, hi: float, margin: float, flag: Flag
) -> NDArray[np.uint8]:
    """``flag`` where ``value`` lies more than ``margin`` outside [lo, hi], else 0 (uint8)."""
    with np.errstate(invalid="ignore"):
        v = np.asarray(value, np.float64)
        out = (v < lo - margin) | (v > hi + margin)
    return np.where(out, np.uint8(flag), np.uint8(0))


def invalid_flag(values: ArrayLike) -> NDArray[np.uint8]:
    """``Flag.INVALID`` where ``values`` is not finite, else 0 (uint8)."""
    return np.where(np.isfinite(values), np.uint8(0), np.uint8(Flag.INVALID))


def table_conditions(table: SweepTable, defaults: Conditions) -> Conditions:
    """The conditions of a table's readings: its optional columns (``ambient_temp_c``,
    ``humidity_pct``, ``emissivity``, ``reflected_temp_c``) per row, ``defaults`` for what it
    lacks."""
    given = {
        name: table[name]
        for name in ("ambient_temp_c", "humidity_pct", "emissivity", "reflected_temp_c")
        if name in table
    }
    return defaults.replace(**given) if given else defaults


def apply_to_table(model: CompensationModel, table: SweepTable) -> Compensated:
    """Compensate every row of a readings table (with its optional condition columns)."""
    return model.apply(
        table["measured_temp_c"],
        table["vox_temp_c"],
        table["distance_m"],
        table_conditions(table, model.conditions),
    )


def names_of(value: int, kind: type[IntFlag] = Flag) -> list[str]:
    """Lower-case names of the flags of ``kind`` set in ``value``, lowest bit first."""
    return [m.name.lower() for m in kind(value) if m.name]


def flag_names(flags: ArrayLike) -> list[str]:
    """Readable flags per reading: ``ok`` or names joined by ``|``."""
    return ["|".join(names_of(int(f))) or "ok" for f in np.asarray(flags, dtype=np.uint8).ravel()]


def check_sweep(table: SweepTable) -> None:
    """A sweep a model can be fitted on: rows, the required columns, no negative distance."""
    if len(table) == 0:
        raise InputError(f"{table.source}: no rows to fit")
    for name in REQUIRED:
        if name not in table:
            raise InputError(f"{table.source}: missing column {name}")
    if np.any(table["distance_m"] < 0):
        raise InputError(
            f"{table.source}: {line_of(table, int(np.argmax(table['distance_m'] < 0)))}"
            "distance_m < 0"
        )


def line_of(table: SweepTable, i: int) -> str:
    """``line N: `` of row ``i`` in the file the table was read from (nothing if built)."""
    return f"line {table.lines[i]}: " if table.lines is not None else ""
