"""Measurements on disk: per fused frame, one JSON line (``measurements.jsonl``), alarm events
(``alarms.jsonl``) and a hotspot table (``hotspots.csv``, one row per hotspot and frame); with
line or isotherm ROIs, also ``lines.csv`` (one row per line and frame: its length, max and
where) and ``isotherms.csv`` (one row per isotherm and frame: its area), made at the first
frame that has them (the profiles themselves are in the JSON lines)."""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from ..csvfile import CsvWriter

FILES = ("measurements.jsonl", "alarms.jsonl", "hotspots.csv")
"""What a measurements folder holds: one JSON line per frame, one per alarm event, and one
CSV row per hotspot and frame."""
SHAPE_FILES = ("lines.csv", "isotherms.csv")
"""What it holds besides with line or isotherm ROIs (:data:`LINE_COLUMNS`,
:data:`ISOTHERM_COLUMNS`)."""
ALL_FILES = FILES + SHAPE_FILES

LINE_COLUMNS = (
    "frame",
    "thermal_time_s",
    "name",
    "length_m",
    "max_c",
    "max_at_m",
    "max_u",
    "max_v",
    "n",
    "gap_px",
)
ISOTHERM_COLUMNS = ("frame", "thermal_time_s", "name", "above_c", "area_cm2", "n", "max_c")

HOTSPOT_COLUMNS = (
    "frame",
    "thermal_time_s",
    "vox_temp_c",
    "label",
    "max_c",
    "mean_c",
    "x_m",
    "y_m",
    "z_m",
    "distance_m",
    "area_m2",
    "thermal_px",
    "resolvable",
    "power_w",
    "flags",
)


def jsonable(x: Any) -> Any:
    """Plain, strict-JSON data: numpy scalars to Python, NaN and infinities to None."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    value = x.item() if hasattr(x, "item") else x
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


@dataclass(frozen=True)
class FrameLines:
    """What one fused frame adds to each file: its ``measurements.jsonl`` line and its
    ``alarms.jsonl`` lines as text (each ended by its newline), and its ``hotspots.csv`` rows
    (:data:`HOTSPOT_COLUMNS` -> the cell's text)."""

    frame: str
    alarms: list[str]
    hotspots: list[dict[str, str | int]]
    lines: list[dict[str, str | int]] = field(default_factory=list)
    isotherms: list[dict[str, str | int]] = field(default_factory=list)

    @classmethod
    def of(cls, fused: Any) -> FrameLines:
        """The lines of a :class:`~thermodepth.pipeline.FusedFrame`."""
        rows: list[dict[str, str | int]] = []
        for h in fused.hotspots:
            x, y, z = h.centroid_m
            rows.append(
                {
                    "frame": fused.index,
                    "thermal_time_s": f"{fused.thermal_time_s:.4f}",
                    "vox_temp_c": f"{fused.vox_temp_c:.2f}",
                    "label": h.label,
                    "max_c": f"{h.max_c:.3f}",
                    "mean_c": f"{h.mean_c:.3f}",
                    "x_m": f"{x:.4f}",
                    "y_m": f"{y:.4f}",
                    "z_m": f"{z:.4f}",
                    "distance_m": f"{h.distance_m:.4f}",
                    "area_m2": f"{h.area_m2:.6g}",
                    "thermal_px": h.thermal_px,
                    "resolvable": int(h.resolvable),
                    "power_w": f"{h.power_w:.4g}",
                    "flags": h.flags,
                }
            )
        when = f"{fused.thermal_time_s:.4f}"
        lines: list[dict[str, str | int]] = [
            {
                "frame": fused.index,
                "thermal_time_s": when,
                "name": p.name,
                "length_m": f"{p.length_m:.4f}",
                "max_c": f"{p.max_c:.3f}",
                "max_at_m": f"{p.max_at_m:.4f}",
                "max_u": "" if p.max_px is None else p.max_px[0],
                "max_v": "" if p.max_px is None else p.max_px[1],
                "n": p.n,
                "gap_px": p.gap_px,
            }
            for p in getattr(fused, "lines", ())
        ]
        isotherms: list[dict[str, str | int]] = [
            {
                "frame": fused.index,
                "thermal_time_s": when,
                "name": i.name,
                "above_c": f"{i.above_c:g}",
                "area_cm2": f"{i.area_cm2:.3f}",
                "n": i.n,
                "max_c": f"{i.max_c:.3f}",
            }
            for i in getattr(fused, "isotherms", ())
        ]
        return cls(
            json.dumps(jsonable(fused.summary())) + "\n",
            [json.dumps(jsonable(event)) + "\n" for event in fused.events],
            rows,
            lines,
            isotherms,
        )


class MeasurementWriter:
    """Writes the measurements of fused frames into ``out_dir`` as they come; ``close()``
    (or ``with``) flushes, and with ``sync`` also has the files on disk (fsync) before it
    returns. Every line is complete when written."""

    def __init__(self, out_dir: str | Path, sync: bool = False) -> None:
        self.sync = sync
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        frames, alarms, hotspots = (out / name for name in FILES)
        self._frames = open(frames, "w", encoding="utf-8")  # noqa: SIM115
        self._alarms = open(alarms, "w", encoding="utf-8")  # noqa: SIM115
        self._hotspots = open(hotspots, "w", newline="", encoding="utf-8")  # noqa: SIM115
        self._table = CsvWriter(self._hotspots, HOTSPOT_COLUMNS)
        self._table.header()
        self._out = out
        self._shapes: dict[str, tuple[TextIO, CsvWriter]] = {}  # made when first needed

    def write(self, fused: Any) -> None:
        """One fused frame (a :class:`~thermodepth.pipeline.FusedFrame`)."""
        self.write_lines(FrameLines.of(fused))

    def write_lines(self, lines: FrameLines) -> None:
        """One frame's lines (:class:`FrameLines`)."""
        self._frames.write(lines.frame)
        self._alarms.writelines(lines.alarms)
        self._table.rows(lines.hotspots)
        for name, columns, rows in (
            (SHAPE_FILES[0], LINE_COLUMNS, lines.lines),
            (SHAPE_FILES[1], ISOTHERM_COLUMNS, lines.isotherms),
        ):
            if rows:
                self._shape_table(name, columns).rows(rows)
        # whole lines on disk as each frame ends: a killed run keeps every frame it measured
        for f in self._files:
            f.flush()

    @property
    def _files(self) -> list[TextIO]:
        return [self._frames, self._alarms, self._hotspots, *(f for f, _ in self._shapes.values())]

    def _shape_table(self, name: str, columns: tuple[str, ...]) -> CsvWriter:
        if name not in self._shapes:
            f = open(self._out / name, "w", newline="", encoding="utf-8")  # noqa: SIM115
            table = CsvWriter(f, columns)
            table.header()
            self._shapes[name] = (f, table)
        return self._shapes[name][1]

    def close(self) -> None:
        for f in self._files:
            if self.sync:
                f.flush()
                os.fsync(f.fileno())
            f.close()

    def __enter__(self) -> MeasurementWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
