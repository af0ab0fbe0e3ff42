"""``thermodepth compile``: numba's kernels compiled into their cache on disk now, so that no
later command or rig compiles them at its start (after an install, in an image's build,
before a test suite's workers start; cold, the registration's take ~40 s and the
simulator's ~20 s of one core, cached ~1 s).

Two parts that share nothing, so that two processes can compile them side by side:
``pipeline`` (registration, radiometry: :meth:`~thermodepth.pipeline.Pipeline.warm_up`) and
``sim`` (a simulated pair rendered, its IR image too).
"""

from __future__ import annotations

import time
from collections.abc import Callable

PARTS = ("pipeline", "sim")


def _pipeline() -> None:
    from ..pipeline import Pipeline, Settings
    from ..sim import default_calibration

    Pipeline(Settings(), default_calibration()).warm_up()


def _sim() -> None:
    from ..sources import open_source

    with open_source("sim", frames=1, with_ir=True) as source:
        list(source)


_COMPILE: dict[str, Callable[[], None]] = {"pipeline": _pipeline, "sim": _sim}


def compile_kernels(parts: tuple[str, ...] = PARTS) -> list[str]:
    """Compile (or load from numba's cache) the kernels of ``parts``; a line each, with its
    time."""
    lines = []
    for part in parts:
        t0 = time.perf_counter()
        _COMPILE[part]()
        lines.append(f"{part}: kernels ready in {time.perf_counter() - t0:.1f} s")
    return lines


__all__ = ["PARTS", "compile_kernels"]
