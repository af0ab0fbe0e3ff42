"""Compensation on whole frames: a 160x120 reading with one VOx temperature and a per-pixel
distance map (what the pipeline does every frame). Target: <= 1 ms.

Peer: converting the same frame's counts to temperature with emissivity and a per-pixel
distance (radiometry alone), which every method needs anyway.
"""

from __future__ import annotations

import numpy as np

from thermodepth.compensation import PaperModel, RadianceModel
from thermodepth.evaluation import training_sweep
from thermodepth.radiometry import ObjectParams, RadiometryParams, raw_to_celsius

from .common import measure, report


def main() -> None:
    ours = RadianceModel.fit(training_sweep(samples=150))
    assert isinstance(ours, RadianceModel)
    paper = PaperModel.preset_2022()
    rng = np.random.default_rng(0)
    counts = rng.uniform(8200, 8800, (120, 160))
    measured = rng.uniform(30.0, 45.0, (120, 160))
    distance = rng.uniform(0.3, 3.0, (120, 160)).astype(np.float32)
    params = RadiometryParams(obj=ObjectParams(0.95, distance, 298.15, 298.15, 0.5))
    timings = [
        measure(
            "ours (radiance): apply_counts",
            lambda: ours.apply_counts(counts, 33.0, distance),
            n=200,
        ),
        measure(
            "ours (radiance): apply (from readings)",
            lambda: ours.apply(measured, 33.0, distance),
            n=200,
        ),
        measure("paper: apply", lambda: paper.apply(measured, 33.0, distance), n=200),
        measure("radiometry alone (peer)", lambda: raw_to_celsius(counts, params), n=200),
    ]
    report(
        "compensation, 160x120 frame with a distance map",
        timings,
        peer="radiometry alone (peer)",
        notes={"target": "<= 1 ms per frame"},
    )
