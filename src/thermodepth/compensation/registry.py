"""The compensation methods by name (``COMPENSATION_METHODS``), published presets, and
fitting one on a sweep."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from ..conditions import Conditions
from ..errors import FieldError
from ..sweep import SweepTable
from .base import CompensationModel
from .none import NoCompensation
from .paper import PaperModel
from .radiance import RadianceModel


class ModelClass(Protocol):
    """What a method registers: a class that fits on a sweep and reads its file mapping."""

    method: str

    def fit(
        self,
        table: SweepTable,
        /,
        *,
        conditions: Conditions | None = None,
        reference_temp_c: float | None = None,
    ) -> CompensationModel: ...

    def from_dict(self, data: dict[str, Any], /) -> CompensationModel: ...


COMPENSATION_METHODS: dict[str, ModelClass] = {
    "radiance": RadianceModel,  # ours (the default)
    "paper": PaperModel,  # Lin & Yao 2022, eq. 20
    "none": NoCompensation,  # physics at each distance, the VOx effect left in
}
"""Compensation models by name; a new one is a class in its own file of this package with
the protocol's methods (:class:`~.base.CompensationModel`), ``fit`` and ``from_dict``."""

PRESETS: dict[str, Callable[[], CompensationModel]] = {"paper2022": PaperModel.preset_2022}
"""Published models by name."""


def method_class(method: str) -> ModelClass:
    """The class of a method; FieldError (``method``) naming the choices."""
    if method not in COMPENSATION_METHODS:
        raise FieldError(
            "method", f"unknown {method!r}; choose from {sorted(COMPENSATION_METHODS)}"
        )
    return COMPENSATION_METHODS[method]


def fit(
    table: SweepTable,
    method: str = "radiance",
    conditions: Conditions | None = None,
    reference_temp_c: float | None = None,
) -> CompensationModel:
    """Fit ``method`` (``COMPENSATION_METHODS``) on a sweep. ``conditions``: those of rows
    that leave them out; ``reference_temp_c``: the one target temperature the paper's method
    fits at (default 39 C if present)."""
    return method_class(method).fit(table, conditions=conditions, reference_temp_c=reference_temp_c)


def preset(name: str) -> CompensationModel:
    """A published model (``PRESETS``); FieldError (``preset``) naming the choices."""
    if name not in PRESETS:
        raise FieldError("preset", f"unknown {name!r}; choose from {sorted(PRESETS)}")
    return PRESETS[name]()
