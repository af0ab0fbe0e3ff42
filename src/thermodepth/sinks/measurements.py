"""Measurements on disk as a sink: ``measurements.jsonl``, ``alarms.jsonl`` and
``hotspots.csv`` in a folder (:mod:`thermodepth.io.measurements`), every line on disk as
each frame ends."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from ..io.measurements import FILES, MeasurementWriter
from ..pipeline import FusedFrame
from .base import BaseSink, RunContext, SessionResult


class MeasurementsSink(BaseSink):
    """Writes every fused frame's measurements into ``out_dir`` (created if needed)."""

    def __init__(self, out_dir: str | Path) -> None:
        self.out_dir = Path(out_dir)
        self.writer: MeasurementWriter | None = None

    def check(self) -> None:
        if self.out_dir.exists() and not self.out_dir.is_dir():
            raise InputError(f"{self.out_dir}: not a directory (measurements go into a directory)")

    def open(self, context: RunContext) -> None:
        self.check()
        try:
            self.writer = MeasurementWriter(self.out_dir)
        except OSError as exc:
            raise InputError(
                f"{self.out_dir}: cannot write measurements ({exc.strerror or exc})"
            ) from None

    def frame(self, fused: FusedFrame) -> None:
        assert self.writer is not None, "open the sink first"
        self.writer.write(fused)

    def close(self, result: SessionResult) -> None:
        if self.writer is not None:
            self.writer.close()

    def summary(self) -> str:
        return f"wrote {', '.join(FILES)} to {self.out_dir}"
