"""Compensation of distance and VOx (sensor) temperature: the paper's method and ours.

A thermal camera's uncompensated reading of a target drifts with the temperature of its own
vanadium-oxide focal plane (the paper's x, "VOx temperature") and falls with distance (air
absorbs). Each model turns a reading, or raw counts, into the target's true temperature given
x and the distance (:class:`~.base.CompensationModel`); models are fitted on a sweep
(``thermodepth.sweep``) and saved as versioned files.

``COMPENSATION_METHODS`` (one file each):

- ``"radiance"`` (ours, :mod:`.radiance`): the sensor's gain and offset in count space as
  polynomials in x, physics for the air path; carries over to distances and target
  temperatures it was not fitted on.
- ``"paper"`` (Lin & Yao 2022, eq. 20, :mod:`.paper`): a ln(x) + b per calibrated distance at
  one reference temperature; the published coefficients are the preset ``paper2022``.
- ``"none"`` (:mod:`.none`): physics at each distance only, the baseline.

:mod:`.files` saves and loads models, :mod:`.scoring` scores them (the paper's Table 6 figure
and stricter ones), :mod:`.tables` recomputes the paper's own Tables 1-6.
"""

from .base import (
    Compensated,
    CompensationModel,
    Flag,
    apply_to_table,
    flag_names,
    names_of,
    table_conditions,
)
from .files import load_model, save_model
from .none import NoCompensation
from .paper import PaperModel
from .radiance import RadianceModel
from .registry import COMPENSATION_METHODS, PRESETS, fit, method_class, preset
from .scoring import DistanceScore, by_vox, evaluation_report, overall, score
from .tables import PAPER_TABLE6, paper_tables, paper_tables_report

__all__ = [
    "COMPENSATION_METHODS",
    "PAPER_TABLE6",
    "PRESETS",
    "Compensated",
    "CompensationModel",
    "DistanceScore",
    "Flag",
    "NoCompensation",
    "PaperModel",
    "RadianceModel",
    "apply_to_table",
    "by_vox",
    "evaluation_report",
    "fit",
    "flag_names",
    "load_model",
    "method_class",
    "names_of",
    "overall",
    "paper_tables",
    "paper_tables_report",
    "preset",
    "save_model",
    "score",
    "table_conditions",
]
