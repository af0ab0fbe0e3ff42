"""Data from any rig (``folder:PATH``): a folder of depth and thermal images with ``rig.yaml`` and
``frames.csv`` (:mod:`thermodepth.io.folder`), as a source of FramePairs.

Pairs are made row by row, or, when every row gives ``depth_time_s`` and ``thermal_time_s``, in
time, by the same rule as live cameras (each thermal frame with the nearest depth frame, pairs
further apart than ``max_skew_s`` dropped and counted). Rows without times are stamped with
their number (one a second). A row that cannot be read is one warning line naming the row and
the file, skipped and counted (``folder_bad_rows``); an image whose size differs from
rig.yaml's stops the source with one line naming it.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..calibration import Calibration
from ..errors import InputError
from ..frames import DepthFrame, Match, StreamEvent, ThermalFrame, pair_of
from ..io.folder import (
    FRAMES_FILE,
    RIG_FILE,
    Row,
    RowError,
    check_row,
    depth_image,
    read_rows,
    telemetry_of,
    thermal_image,
)
from .base import Source
from .pairing import DEFAULT_MAX_SKEW_S, StreamPairer


class FolderSource(Source):
    """The pairs of an image folder (module docstring). warn: where the line of each row that
    cannot be read goes."""

    def __init__(
        self,
        path: str | Path,
        warn: Callable[[str], None] | None = None,
        max_skew_s: float = DEFAULT_MAX_SKEW_S,
    ) -> None:
        self.folder = Path(path)
        if not self.folder.is_dir():
            raise InputError(f"{self.folder}: no such folder")
        self.name = f"folder:{path}"
        self.files = (self.folder,)
        self.rig = self.calibration = Calibration.load(self.folder / RIG_FILE)
        self.rows = read_rows(self.folder)
        self.warn = warn or (lambda line: None)
        self.bad_rows = 0
        timed = bool(self.rows) and all(
            r.depth_time_s is not None and r.thermal_time_s is not None for r in self.rows
        )
        self.pairer = StreamPairer(max_skew_s) if timed else None
        self.pairing = None if self.pairer is None else self.pairer.stats
        self.paired_by = None if timed else "the rows of frames.csv"

    def counters(self) -> dict[str, int]:
        return {"folder_bad_rows": self.bad_rows}

    def settings(self) -> dict[str, Any]:
        return {"source": self.name, "rows": len(self.rows), "paired_in_time": bool(self.pairer)}

    def _frames(self, index: int, row: Row) -> tuple[DepthFrame, ThermalFrame] | None:
        """The row's two frames, or None (said, counted) when it cannot be read."""
        where = f"{self.folder / FRAMES_FILE}: line {row.line}"
        cal = self.rig
        try:
            check_row(row, str(self.folder / FRAMES_FILE))
            depth = depth_image(row.depth, where, cal.depth.shape)
            ir = None if row.ir is None else depth_image(row.ir, where, cal.depth.shape, np.uint8)
            values, float_kelvin = thermal_image(row.thermal, where, cal.thermal.shape)
        except RowError as exc:
            self.bad_rows += 1
            self.warn(f"{exc}; the row is skipped")
            return None
        t_depth = float(index) if row.depth_time_s is None else row.depth_time_s
        t_thermal = float(index) if row.thermal_time_s is None else row.thermal_time_s
        telemetry = telemetry_of(index, row.fpa_temp_c, row.in_ffc, float_kelvin)
        thermal = ThermalFrame(values, t_thermal, index, telemetry)
        return DepthFrame(depth, t_depth, index, ir), thermal

    def events(self) -> Iterator[StreamEvent]:
        if self.pairer is None:  # row by row
            pairs = 0
            for i, row in enumerate(self.rows):
                frames = self._frames(i, row)
                if frames is not None:
                    depth, thermal = frames
                    yield Match(depth, thermal, pair_of(depth, thermal, pairs))
                    pairs += 1
            return
        # the frames as they would arrive from two cameras, in time order; rows are read in
        # the order of their first time, and a frame waits only until no later row can hold
        # an earlier one
        first = [min(r.depth_time_s or 0.0, r.thermal_time_s or 0.0) for r in self.rows]
        order = sorted(range(len(self.rows)), key=first.__getitem__)
        waiting: list[tuple[float, int, DepthFrame | ThermalFrame]] = []
        tick = itertools.count()  # ties in time keep their order, frames are not compared
        for k, i in enumerate(order):
            both = self._frames(i, self.rows[i])
            for frame in both or ():
                heapq.heappush(waiting, (frame.time_s, next(tick), frame))
            horizon = first[order[k + 1]] if k + 1 < len(order) else float("inf")
            while waiting and waiting[0][0] <= horizon:
                frame = heapq.heappop(waiting)[2]
                yield frame
                if isinstance(frame, DepthFrame):
                    yield from self.pairer.add_depth(frame)
                else:
                    yield from self.pairer.add_thermal(frame)
        yield from self.pairer.flush()
