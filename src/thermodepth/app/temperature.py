"""``thermodepth temperature``: raw counts to object temperature."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..conditions import Conditions, Radiometry, check_condition
from ..errors import FieldError
from ..radiometry import PLANCK_PRESETS


def counts_to_celsius(
    counts: Sequence[float],
    conditions: Conditions | None = None,
    distance_m: float = 0.0,
    preset: str = "paper2022",
    method: str = "flir",
) -> list[float]:
    """Object temperatures (C) of raw counts seen through ``conditions`` (default: a
    blackbody in 25 C air at 50 % humidity) from ``distance_m``, with the Planck constants
    ``preset`` and the radiometric ``method``; NaN for counts no temperature gives.
    FieldError names a bad argument."""
    if preset not in PLANCK_PRESETS:
        raise FieldError("preset", f"unknown {preset!r}; choose from {sorted(PLANCK_PRESETS)}")
    check_condition("distance_m", distance_m)
    radiometry = Radiometry(
        conditions or Conditions(emissivity=1.0), PLANCK_PRESETS[preset], method
    )
    return [float(t) for t in radiometry.celsius(np.asarray(counts), distance_m)]
