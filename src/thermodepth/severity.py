"""Severity classes: a reading judged by its temperature difference (delta-T).

A thermographer does not judge a joint by its temperature alone but by how much hotter it is
than a similar part under the same load, or than the air. A *criteria table* turns that
difference into a class: a priority (1 the most urgent) and its words. Two are built in, from
the NETA Maintenance Testing Specifications (ANSI/NETA MTS, table 100.18, "Thermographic
survey suggested actions based on temperature rise"):

- ``neta-similar``, against a similar component under similar load: 1-3 C priority 4
  "possible deficiency", 4-15 C priority 3 "probable deficiency", > 15 C priority 1
  "major discrepancy";
- ``neta-ambient``, against the air: 1-10 C priority 4, 11-20 C priority 3, 21-40 C priority 2,
  > 40 C priority 1.

A table is a list of rows in rising order, each with ``from_c`` (delta-T >= it) or ``above_c``
(delta-T > it), a ``priority`` and a ``label``; a delta-T takes the class of the last row it
reaches, none below the first. The published whole-degree ranges are read as contiguous, each
stated upper bound inclusive and the next class beginning just above it, as the tables' last
row (> 15 C) reads: 3.0 C is priority 4, 3.5 C and 15.0 C priority 3, 15.1 C priority 1;
below 1 C no class.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from pydantic import Field, model_validator

from .schema import StrictSchema


class SeverityRow(StrictSchema):
    """One row of a criteria table: where the class begins (``from_c``: delta-T at or above
    it; ``above_c``: strictly above it), its ``priority`` (1 the most urgent) and its
    ``label``."""

    from_c: float | None = None
    above_c: float | None = None
    priority: int = Field(ge=1, le=99)
    label: str = Field(min_length=1)

    @model_validator(mode="after")
    def _one_bound(self) -> SeverityRow:
        if (self.from_c is None) == (self.above_c is None):
            raise ValueError("give exactly one of from_c (delta-T >= C) or above_c (delta-T > C)")
        return self

    @property
    def bound(self) -> tuple[float, bool]:
        """(the bound in C, whether delta-T must be strictly above it)."""
        if self.above_c is not None:
            return self.above_c, True
        assert self.from_c is not None
        return self.from_c, False

    def reached(self, delta_t_c: float) -> bool:
        value, strict = self.bound
        return delta_t_c > value if strict else delta_t_c >= value


def check_table(rows: Sequence[SeverityRow]) -> str | None:
    """Why ``rows`` cannot be a criteria table (None when they can): at least one row; bounds
    rising (a ``from_c`` and an ``above_c`` of the same value in that order); priorities not
    rising with delta-T (a greater difference is never less urgent)."""
    if not rows:
        return "a table needs at least one row"
    for k in range(1, len(rows)):
        (a, a_strict), (b, b_strict) = rows[k - 1].bound, rows[k].bound
        if not (a < b or (a == b and not a_strict and b_strict)):
            return f"row {k}: its bound ({b:g} C) must be above row {k - 1}'s ({a:g} C)"
        if rows[k].priority > rows[k - 1].priority:
            return (
                f"row {k}: priority {rows[k].priority} is less urgent than row {k - 1}'s "
                f"({rows[k - 1].priority}) at a greater delta-T"
            )
    return None


def _rows(*rows: tuple[str, float, int, str]) -> tuple[SeverityRow, ...]:
    return tuple(
        SeverityRow(**{key: bound}, priority=p, label=label) for key, bound, p, label in rows
    )


BUILT_IN: dict[str, tuple[SeverityRow, ...]] = {
    "neta-similar": _rows(
        ("from_c", 1.0, 4, "possible deficiency"),
        ("above_c", 3.0, 3, "probable deficiency"),
        ("above_c", 15.0, 1, "major discrepancy"),
    ),
    "neta-ambient": _rows(
        ("from_c", 1.0, 4, "possible deficiency"),
        ("above_c", 10.0, 3, "probable deficiency"),
        ("above_c", 20.0, 2, "deficiency"),
        ("above_c", 40.0, 1, "major discrepancy"),
    ),
}
"""The built-in criteria tables (module docstring). NETA's words for priority 2 against the
air are "monitor continuously until corrective measures can be accomplished"; the label says
"deficiency"."""

AMBIENT = "ambient"
"""What a class says it was measured against when that is the settings' air temperature."""
NEEDS_ROI = ("neta-similar",)
"""The built-in tables that compare with a similar component: ``relative_to`` is needed."""


class SeveritySettings(StrictSchema):
    """An ROI's severity: which ``criteria`` table, against what (``relative_to``: another
    ROI's name, whose same ``stat`` is the reference, e.g. the air seen in an ROI or a similar
    phase; None: the settings' ``radiometry.ambient_temp_c``), and which statistic of the two
    (default ``max``)."""

    criteria: str
    relative_to: str | None = None
    stat: Literal["max", "mean", "min"] = "max"


@dataclass(frozen=True)
class SeverityClass:
    """An ROI's class in one frame: ``delta_t_c`` (C; NaN when a reading is missing),
    ``priority`` (None: below the table's first row, or no delta-T) and ``label``
    (``"no deficiency"`` below the first row, ``"no reading"`` without a delta-T), the
    ``criteria`` and what it was measured ``relative_to``."""

    criteria: str
    relative_to: str
    delta_t_c: float
    priority: int | None
    label: str

    def as_dict(self) -> dict[str, Any]:
        return {
            "criteria": self.criteria,
            "relative_to": self.relative_to,
            "delta_t_c": round(self.delta_t_c, 3) if np.isfinite(self.delta_t_c) else None,
            "priority": self.priority,
            "label": self.label,
        }


def classify(rows: Sequence[SeverityRow], delta_t_c: float) -> tuple[int | None, str]:
    """The (priority, label) of a delta-T (C) in a criteria table: the last row it reaches;
    (None, ``"no deficiency"``) below the first; (None, ``"no reading"``) for NaN."""
    if not np.isfinite(delta_t_c):
        return None, "no reading"
    found = None
    for row in rows:
        if row.reached(delta_t_c):
            found = row
    return (None, "no deficiency") if found is None else (found.priority, found.label)


class SeverityJudge:
    """The severity of each ROI that asks for one, per frame.

    tables: the built-in and user tables by name; severities: ROI name -> its settings;
    ambient_temp_c: the air's temperature for ``relative_to: ambient``.
    """

    def __init__(
        self,
        tables: Mapping[str, Sequence[SeverityRow]],
        severities: Mapping[str, SeveritySettings],
        ambient_temp_c: float,
    ) -> None:
        self.tables = dict(tables)
        self.severities = dict(severities)
        self.ambient_temp_c = float(ambient_temp_c)

    def judge(self, stats: Mapping[str, Any]) -> dict[str, SeverityClass]:
        """The class of each ROI with a severity, from the frame's ROI statistics by name
        (objects with ``n`` and ``max_c``/``mean_c``/``min_c``; ``n == 0``: no reading)."""
        out = {}
        for name, sev in self.severities.items():
            value = _stat(stats.get(name), sev.stat)
            if sev.relative_to is None:
                reference = self.ambient_temp_c
            else:
                reference = _stat(stats.get(sev.relative_to), sev.stat)
            delta = value - reference
            priority, label = classify(self.tables[sev.criteria], delta)
            against = sev.relative_to or AMBIENT
            out[name] = SeverityClass(sev.criteria, against, delta, priority, label)
        return out


def _stat(roi: Any, stat: str) -> float:
    if roi is None or not roi.n:
        return float("nan")
    return float(getattr(roi, f"{stat}_c"))


def all_tables(user: Mapping[str, Sequence[SeverityRow]]) -> dict[str, Sequence[SeverityRow]]:
    """The built-in tables and the settings' own (``severity_criteria``)."""
    return {**BUILT_IN, **user}


def settings_problem(
    user: Mapping[str, Sequence[SeverityRow]],
    severities: Mapping[str, SeveritySettings],
    roi_names: Sequence[str],
) -> str | None:
    """The first problem (one line naming the field) of the settings' severity parts, or
    None: a user table's name that is a built-in's, a bad table (:func:`check_table`), an ROI's
    criteria that name no table, or a ``relative_to`` that is no other ROI (or is missing for
    a table against a similar component)."""
    for name, rows in user.items():
        if name in BUILT_IN:
            return f"severity_criteria.{name}: a built-in table's name; choose another"
        why = check_table(rows)
        if why:
            return f"severity_criteria.{name}: {why}"
    known = all_tables(user)
    for roi, sev in severities.items():
        where = f"roi {roi!r}: severity"
        if sev.criteria not in known:
            return f"{where}.criteria: unknown {sev.criteria!r}; choose from {sorted(known)}"
        if sev.relative_to is None and sev.criteria in NEEDS_ROI:
            return f"{where}.relative_to: {sev.criteria} compares with a similar component's ROI"
        if sev.relative_to is not None and (
            sev.relative_to == roi or sev.relative_to not in roi_names
        ):
            others = sorted(set(roi_names) - {roi})
            return (
                f"{where}.relative_to: {sev.relative_to!r} is not another ROI's name "
                f"({', '.join(others) or 'none'})"
            )
    return None
