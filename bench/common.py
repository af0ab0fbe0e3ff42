"""Timing helpers for benchmarks: medians and p90 over repeated runs, printed as tables."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike
from rich.console import Console
from rich.table import Table

OUT = Path("bench-out")
console = Console()


@dataclass
class Timing:
    """Milliseconds per call: median and 90th percentile over ``n`` timed calls."""

    name: str
    median_ms: float
    p90_ms: float
    n: int

    @classmethod
    def of(cls, name: str, seconds: ArrayLike) -> Timing:
        """The timing of calls that took ``seconds`` each."""
        t = np.asarray(seconds)
        return cls(name, float(np.median(t) * 1e3), float(np.percentile(t, 90) * 1e3), t.size)


def counting(fn: Callable[[int], object]) -> Callable[[], object]:
    """``fn`` called with 0, 1, 2, ... on successive calls (which frame or row to use)."""
    calls = iter(range(10**9))
    return lambda: fn(next(calls))


def measure(name: str, fn: Callable[[], object], n: int = 30, warmup: int = 3) -> Timing:
    """Time ``fn`` ``n`` times after ``warmup`` untimed calls (JIT compile, caches)."""
    for _ in range(warmup):
        fn()
    times = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        fn()
        times[i] = time.perf_counter() - t0
    return Timing.of(name, times)


def measure_extra(
    name: str, base: Callable[[], object], fn: Callable[[], object], n: int = 300
) -> Timing:
    """What ``fn`` costs more than ``base``: the two called in turn ``n`` times (after a few
    untimed calls), the difference of each turn timed; in turn, so that the machine's drift
    falls on both alike."""
    for _ in range(5):
        base()
        fn()
    extra = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        base()
        t1 = time.perf_counter()
        fn()
        extra[i] = (time.perf_counter() - t1) - (t1 - t0)
    return Timing.of(name, extra)


def report(
    title: str,
    timings: list[Timing],
    peer: str | None = None,
    notes: dict[str, object] | None = None,
) -> None:
    """Print a table (with each row's median as a ratio of the ``peer`` row's median) and save
    it as JSON in bench-out/."""
    ref = next((t.median_ms for t in timings if t.name == peer), None)
    table = Table(title=title)
    for col in ("what", "median ms", "p90 ms", "n") + ((f"x {peer}",) if ref else ()):
        table.add_column(col, justify="left" if col == "what" else "right")
    for t in timings:
        row = [t.name, f"{t.median_ms:.2f}", f"{t.p90_ms:.2f}", str(t.n)]
        if ref:
            row.append(f"{t.median_ms / ref:.2f}")
        table.add_row(*row)
    console.print(table)
    for k, v in (notes or {}).items():
        console.print(f"  {k}: {v}")
    OUT.mkdir(exist_ok=True)
    slug = "".join(c if c.isalnum() else "_" for c in title.lower()).strip("_")
    (OUT / f"{slug}.json").write_text(
        json.dumps(
            {
                "title": title,
                "peer": peer,
                "timings": [asdict(t) for t in timings],
                "notes": {k: str(v) for k, v in (notes or {}).items()},
            },
            indent=2,
        )
    )
