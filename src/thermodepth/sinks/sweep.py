"""Sweep rows as a sink: each pair a source emits read for the reference target
(:class:`~thermodepth.collect.SweepCollector`), each row on disk as soon as it is made
(:class:`~thermodepth.sweep.SweepAppender`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..collect import COLLECTED_COLUMNS, CollectStats, FloatArray, SweepCollector
from ..conditions import Conditions
from ..errors import InputError
from ..frames import Match, StreamEvent
from ..sweep import SweepAppender
from ..target import TargetSpec
from .base import BaseSink, RunContext, SessionResult


@dataclass(frozen=True)
class SweepRequest:
    """What to collect (:class:`~thermodepth.collect.SweepCollector`): the target, its true
    temperature (C), the conditions and the readings per row."""

    target: TargetSpec
    reference_temp_c: float
    conditions: Conditions
    average: int = 1


class SweepSink(BaseSink):
    """Writes the sweep CSV ``out`` (``append``: add to an existing one) from every pair of
    the session, and the target's overlays ``<out stem>_target_NN.png``. ``say`` gets the
    lines on the target (found, lost, changed)."""

    def __init__(
        self,
        out: str | Path,
        request: SweepRequest,
        append: bool = False,
        say: Callable[[str], None] | None = None,
    ) -> None:
        self.out = Path(out)
        self.request = request
        self.writer = SweepAppender(self.out, COLLECTED_COLUMNS, append)
        self.say = say
        self.collector: SweepCollector | None = None

    @property
    def stats(self) -> CollectStats:
        return self.collector.stats if self.collector is not None else CollectStats()

    def check(self) -> None:
        self.writer.check()

    def overlay_path(self, label: str) -> Path:
        """Where the overlay ``label`` (a number, or ``none``) goes."""
        return self.out.parent / f"{self.out.stem}_target_{label}.png"

    def open(self, context: RunContext) -> None:
        from ..figures import plot_target

        calibration = context.source.calibration or context.calibration
        if calibration is None:
            raise InputError(
                f"{context.source.name}: no calibration to register depth to thermal pixels "
                "with; give --calibration"
            )
        r = self.request

        def overlay(temp: FloatArray, mask: NDArray[np.bool_] | None, title: str) -> Path:
            n = len(self.stats.overlays) + 1
            return plot_target(temp, mask, title, self.overlay_path(f"{n:02d}"))

        self.collector = SweepCollector(
            calibration,
            r.target,
            r.reference_temp_c,
            r.conditions,
            r.average,
            overlay,
            self.say,
            context.source.name,
        )

    def event(self, event: StreamEvent) -> None:
        if isinstance(event, Match):
            assert self.collector is not None, "open the sink first"
            for row in self.collector.add(event.pair):
                self.writer.write(row)

    def close(self, result: SessionResult) -> None:
        try:
            if self.collector is not None:
                for row in self.collector.close():
                    self.writer.write(row)
        finally:
            self.writer.close()

    def summary(self) -> str:
        s = self.stats
        return (
            f"wrote {self.writer.rows} rows to {self.out} from {s.pairs} pairs "
            f"({s.ffc_pairs} in FFC, {s.missing_pairs} without the target, {s.moving_pairs} "
            f"with it moving); the target settled in {s.placements} places"
        )
