"""``thermodepth fit-compensation``, ``compensate``, ``evaluate`` and ``paper-tables``."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..compensation import (
    CompensationModel,
    apply_to_table,
    evaluation_report,
    fit,
    flag_names,
    load_model,
    paper_tables_report,
    preset,
    save_model,
)
from ..conditions import Conditions
from ..errors import FieldError
from ..sweep import SweepTable, read_sweep_csv, write_sweep_csv


@dataclass(frozen=True)
class FitOutcome:
    """A fitted (or published) model, written to ``path``, with what to tell the user:
    ``notes`` (what fitting chose, the ranges) and ``warnings`` (what the sweep could not
    teach it)."""

    model: CompensationModel
    path: Path
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def fit_compensation(
    sweep: Path | None,
    out: Path,
    method: str = "radiance",
    preset_name: str | None = None,
    reference_temp_c: float | None = None,
    conditions: Conditions | None = None,
) -> FitOutcome:
    """Fit ``method`` on the sweep CSV ``sweep`` (or take the published ``preset_name``) and
    write it to ``out``. ``conditions``: those of rows that leave them out; bad input raises
    an InputError (FieldError for an argument)."""
    if preset_name is not None:
        model = preset(preset_name)
        save_model(model, out)
        return FitOutcome(model, out, model.summary())
    if sweep is None:
        raise FieldError("sweep", "give a sweep CSV to fit, or a preset")
    table = read_sweep_csv(sweep)
    model = fit(table, method, conditions, reference_temp_c)
    save_model(model, out)
    return FitOutcome(model, out, model.summary(), sweep_warnings(table))


def sweep_warnings(table: SweepTable) -> list[str]:
    """What a sweep cannot teach a model: one VOx temperature (how VOx moves the readings)."""
    vox = np.unique(table["vox_temp_c"])
    if vox.size == 1:
        return [
            f"{table.source}: one VOx temperature ({vox[0]:g} C): the model cannot learn how "
            "VOx moves the readings, and flags readings at any other as vox_outside"
        ]
    return []


def compensate_file(model_path: Path, readings: Path, out: Path) -> tuple[int, int]:
    """Compensate every row of the readings CSV ``readings`` into ``out`` (the readings as
    they came, plus ``compensated_temp_c`` and ``flag``); returns (rows, rows flagged)."""
    model = load_model(model_path)
    table = read_sweep_csv(readings, required=("distance_m", "vox_temp_c", "measured_temp_c"))
    result = apply_to_table(model, table)
    flags = flag_names(result.flag)
    # digits=None: the readings' values as they came (6 digits would round them)
    write_sweep_csv(
        out, table.with_columns(compensated_temp_c=result.temp_c, flag=flags), digits=None
    )
    return len(table), sum(f != "ok" for f in flags)


def evaluate(
    model_path: Path, test: Path, by_vox: bool = False, plot_dir: Path | None = None
) -> dict[str, Any]:
    """Scores of a model on a test sweep (:func:`~thermodepth.compensation.evaluation_report`;
    with ``by_vox`` the layout of the paper's Tables 1-5), and with ``plot_dir`` the paper's
    Figs. 13 and 14 drawn there (their paths under ``figures``)."""
    model = load_model(model_path)
    table = read_sweep_csv(test)
    report = evaluation_report(model, table, 1.0 if by_vox else None)
    if plot_dir is not None:
        from ..figures import plot_vox_curves

        report["figures"] = [str(p) for p in plot_vox_curves(model, table, plot_dir)]
    return report


def paper_tables() -> dict[str, Any]:
    """The paper's Tables 1-5 recomputed into Table 6, with the figures the paper omits."""
    return paper_tables_report()
