"""Pictures from a run: every ``every`` fused frames, and at every alarm, an overlay PNG and
a PLY point cloud in ``<out>/snapshots/`` (``frame_000120.png``, ``frame_000120.ply``),
all on one colour scale (the settings' ``viewer.temp_range_c`` if given, else fixed from the
first frame with temperatures), the settings' ROIs outlined (in red those of the alarms
raised at that frame)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

from ..alarms import RAISED
from ..figures import alarm_rois, display_range_c, plot_overlay
from ..io.pointcloud import write_ply
from ..measure import Roi
from ..pipeline import FusedFrame, Pipeline
from .base import BaseSink, RunContext


def write_snapshot(
    fused: FusedFrame,
    png: Path,
    ply: Path,
    title: str,
    range_c: tuple[float, float],
    rois: Sequence[Roi] = (),
    marked: Mapping[str, str] | None = None,
) -> None:
    """The overlay PNG and the PLY point cloud of a fused frame, coloured on ``range_c``
    (C); the overlay with ``rois`` outlined, in red those in ``marked`` (name: level of the
    raised rule that watches it, :func:`~thermodepth.figures.alarm_rois`)."""
    lo, hi = range_c
    plot_overlay(fused, png, title, lo, hi, rois, marked)
    points, temps = fused.points()
    write_ply(ply, points, temps, lo, hi)


class SnapshotSink(BaseSink):
    """Writes the snapshots of a run into ``out_dir/snapshots`` (see the module docstring);
    ``range_c``: the colour scale (C), None: from the first frame with temperatures."""

    def __init__(
        self, out_dir: str | Path, every: int, range_c: tuple[float, float] | None = None
    ) -> None:
        self.folder = Path(out_dir) / "snapshots"
        self.every = every
        self.range_c = range_c
        self.written = 0
        self.at_alarms = 0
        self._seen = 0
        self._pipeline: Pipeline | None = None

    def open(self, context: RunContext) -> None:
        self._pipeline = context.pipeline

    def frame(self, fused: FusedFrame) -> None:
        self._seen += 1
        alarms = [e["rule"] for e in fused.events if e["event"] in RAISED]
        if fused.in_ffc or not (alarms or (self._seen - 1) % self.every == 0):
            return
        if self.range_c is None:
            self.range_c = display_range_c(fused.temp_depth_c)
        rule = ", ".join(alarms)
        title = f"frame {fused.index}, t {fused.thermal_time_s:.2f} s, VOx {fused.vox_label}"
        title += f": ALARM {rule}" if rule else ""
        png = self.folder / f"frame_{fused.index:06d}.png"
        pipe = self._pipeline
        rois = pipe.rois if pipe is not None else []
        marked = alarm_rois(pipe.alarms.rules, alarms) if pipe is not None else {}
        write_snapshot(fused, png, png.with_suffix(".ply"), title, self.range_c, rois, marked)
        self.written += 1
        self.at_alarms += bool(alarms)

    def summary(self) -> str:
        return (
            f"wrote {self.written} snapshots ({self.at_alarms} at alarms; overlay PNG and PLY, "
            f"{self.range_c[0]:g}-{self.range_c[1]:g} C) to {self.folder}"
            if self.range_c
            else f"no snapshot written to {self.folder}"
        )
