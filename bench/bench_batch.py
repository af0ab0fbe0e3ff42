"""Batch: many recordings measured again on a dask LocalCluster of 1 and 2 worker processes
against the sequential ``run --source recording:`` of each, in the same process and run.

Recordings of the same simulated live stream (``--depth paired``, 174 pairs each), the
default settings with one alarm rule, batches of 4 and of 8 of them. Times are whole walls
(median of ``RUNS``): the batch's includes starting its cluster (the workers import the
project and load numba's cache) and writing the summary; the sequential run's includes
opening each recording. Pairs per second: of the 8-recording batch (pairs / wall), and at
the margin (the 4 more recordings' pairs / the wall they add), which leaves the start-up out.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from thermodepth.app.batch import BatchOptions, batch
from thermodepth.app.run import RunOptions, run
from thermodepth.io.recording import DEFAULT_CODEC

from .bench_replay import live_events, write
from .common import Timing, report

SIZES = (4, 8)
RUNS = 3
SETTINGS = "hotspots:\n  threshold_c: 50\nalarms:\n  - {name: hot, above_c: 60, for_frames: 3}\n"


def main() -> None:
    tmp = Path(tempfile.mkdtemp(prefix="bench-batch-"))
    try:
        events = live_events(600)
        recordings = []
        for i in range(max(SIZES)):
            write(tmp / f"r{i}.zarr", events, "paired", DEFAULT_CODEC)
            recordings.append(str(tmp / f"r{i}.zarr"))
        settings = tmp / "s.yaml"
        settings.write_text(SETTINGS, encoding="utf-8")
        pairs: dict[int, int] = {}

        def sequential(n: int, k: int) -> None:
            pairs[n] = 0
            for i, rec in enumerate(recordings[:n]):
                out = tmp / f"seq{n}-{k}-{i}"
                pairs[n] += run(RunOptions(f"recording:{rec}", settings, out_dir=out)).frames

        def on_cluster(workers: int, n: int, k: int) -> None:
            out = tmp / f"batch{workers}-{n}-{k}"
            result = batch(BatchOptions(tuple(recordings[:n]), out, settings, workers=workers))
            assert result.pairs == pairs[n] and not result.failed

        sequential(max(SIZES), -1)  # numba caches, imports
        ways = {
            "sequential run": sequential,
            "batch, 1 worker process": lambda n, k: on_cluster(1, n, k),
            "batch, 2 worker processes": lambda n, k: on_cluster(2, n, k),
        }
        timings, notes = [], {}
        for name, fn in ways.items():
            med = {}
            for n in SIZES:
                walls = []
                for k in range(RUNS):
                    t0 = time.perf_counter()
                    fn(n, k)
                    walls.append(time.perf_counter() - t0)
                timing = Timing.of(f"{name}, {n} recordings", np.array(walls))
                timings.append(timing)
                med[n] = timing.median_ms / 1000
            small, big = SIZES
            margin = (pairs[big] - pairs[small]) / (med[big] - med[small])
            notes[name] = (
                f"{pairs[big] / med[big]:.0f} pairs/s over {big} recordings, "
                f"{margin:.0f} pairs/s at the margin"
            )
        report(
            f"batch of {SIZES[0]} and {SIZES[1]} recordings (174 pairs each), wall per batch",
            timings,
            peer=f"sequential run, {SIZES[0]} recordings",
            notes=notes,
        )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
