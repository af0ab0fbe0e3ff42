"""The paper's own figures: its Tables 1-5 (shipped as data) recomputed into Table 6, beside
the published Table 6, with what the paper does not show."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..sweep import SweepTable
from .scoring import overall, score


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
