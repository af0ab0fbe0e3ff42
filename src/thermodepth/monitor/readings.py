"""A rig's readings kept over time: each ROI's maximum, mean and minimum over each UTC minute
(and the hottest spot of the whole view as :data:`WHOLE_VIEW`), a row each in the event
store's readings table (:mod:`.store`), for the inspection report's trends
(:mod:`thermodepth.app.report`).

A rig's thread adds each fused frame (:meth:`MinuteReadings.add`: a few comparisons); a
minute's rows are written when the first frame of the next arrives (and at the rig's stop),
so the store sees a rig's rows once a minute. The ROI's distance (the median depth inside
it, m) is taken from the first frame of each minute: its depth image and the ROI's mask, once
a minute. A frame while the shutter is closed is not a reading.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

import numpy as np

from ..measure import Roi
from ..pipeline import FusedFrame

WHOLE_VIEW = "*"
"""The readings' ROI name for the hottest spot of the whole view (the hotspots' maximum)."""


def minute_of(time_s: float) -> str:
    """The UTC minute a Unix time falls in, as stored: ``2026-11-26T14:35:00+00:00``."""
    when = datetime.fromtimestamp(time_s, timezone.utc).replace(second=0, microsecond=0)
    return when.isoformat()


@dataclass
class _Minute:
    """One ROI's readings of the minute so far."""

    max_c: float = float("-inf")
    min_c: float = float("inf")
    total_c: float = 0.0
    frames: int = 0
    distance_m: float | None = None

    def add(self, max_c: float, mean_c: float, min_c: float) -> None:
        self.max_c, self.min_c = max(self.max_c, max_c), min(self.min_c, min_c)
        self.total_c += mean_c
        self.frames += 1


@dataclass
class MinuteReadings:
    """A rig's readings of the current minute (module docstring); ``write(rows)`` takes a
    finished minute's rows (the store's :meth:`~.store.EventStore.add_readings`)."""

    rig: str
    rois: Sequence[Roi]
    write: Callable[[list[dict[str, Any]]], None]
    minute: str | None = None
    by_roi: dict[str, _Minute] = field(default_factory=dict)

    def add(self, fused: FusedFrame, time_s: float) -> None:
        """A fused frame taken at ``time_s`` (Unix s)."""
        if fused.in_ffc:
            return
        minute = minute_of(time_s)
        if minute != self.minute:
            self.flush()
            self.minute = minute
        first = not self.by_roi
        if fused.hotspots:
            hot = fused.hotspots[0]
            whole = self.by_roi.setdefault(WHOLE_VIEW, _Minute())
            whole.add(hot.max_c, hot.max_c, hot.max_c)
            if whole.distance_m is None:
                whole.distance_m = round(float(hot.distance_m), 3)
        for stats in fused.rois:
            if stats.n:
                self.by_roi.setdefault(stats.name, _Minute()).add(
                    stats.max_c, stats.mean_c, stats.min_c
                )
        if first and self.by_roi:
            self._distances(fused)

    def _distances(self, fused: FusedFrame) -> None:
        """Each ROI's median distance (m) in this frame."""
        depth_m = fused.depth_m
        for roi in self.rois:
            kept = self.by_roi.get(roi.name)
            if kept is None:
                continue
            inside = depth_m[roi.mask(depth_m.shape, depth_m)]
            inside = inside[np.isfinite(inside) & (inside > 0)]
            if inside.size:
                kept.distance_m = round(float(np.median(inside)), 3)

    def flush(self) -> None:
        """Write the minute's rows (none when it had no reading)."""
        if self.minute is None or not self.by_roi:
            return
        rows = [
            {
                "rig": self.rig,
                "roi": name,
                "minute_utc": self.minute,
                "max_c": round(m.max_c, 3),
                "mean_c": round(m.total_c / m.frames, 3),
                "min_c": round(m.min_c, 3),
                "frames": m.frames,
                "distance_m": m.distance_m,
            }
            for name, m in self.by_roi.items()
        ]
        self.by_roi = {}
        self.write(rows)
