"""matplotlib on the file-only Agg backend, for every room that draws a figure (PNG)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray


def pyplot() -> Any:
    """matplotlib.pyplot on the file-only Agg backend (no display needed); imported when a
    figure is drawn, not when the project is."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: str | Path, dpi: int = 120) -> Path:
    """Lay out, write (creating the folder) and close a figure; returns the path."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    if fig.get_layout_engine() is None:  # a figure laid out by its own engine keeps it
        fig.tight_layout()
    fig.savefig(out, dpi=dpi)
    pyplot().close(fig)
    return out


MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")


def distinct_styles(n: int) -> list[tuple[Any, str]]:
    """``n`` (colour, marker) pairs that tell lines apart in colour and in grey print: the
    tab10 colours with a marker each (repeating after 10 and 8)."""
    colors = pyplot().get_cmap("tab10").colors
    return [(colors[i % len(colors)], MARKERS[i % len(MARKERS)]) for i in range(n)]


def temperature_rgb(
    temp_c: NDArray[np.floating], range_c: tuple[float, float], colormap: str = "inferno"
) -> NDArray[np.uint8]:
    """RGB (..., 3) uint8 of temperatures (C) through ``colormap`` over ``range_c``, clipped
    at both ends (NaN takes the bottom colour: callers that show it apart mark it)."""
    from matplotlib import colormaps

    lo, hi = range_c
    scaled = np.clip((np.asarray(temp_c, np.float64) - lo) / max(hi - lo, 1e-6), 0.0, 1.0)
    return (colormaps[colormap](np.nan_to_num(scaled))[..., :3] * 255).round().astype(np.uint8)
