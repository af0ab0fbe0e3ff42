"""A sweep collected from a paired stream: the paper's protocol (section 4) on a real rig.

Each pair whose shutter is open gives one reading of the reference target
(:mod:`thermodepth.target`): its mean apparent temperature (radiometry with the emissivity,
no distance correction: the sweep CSV's ``measured_temp_c``), its distance (the median range
from the thermal camera of the depth pixels that land on it, metres), the VOx (FPA)
temperature from the telemetry (empty when the camera tells none) and the mean raw pixel value
(counts, or the camera's own kelvin units). ``average`` readings in a row make one sweep row
(``n``).

Only a target that holds still is read: a frame whose target moved since the previous frame
(:data:`STILL_OVERLAP`, :data:`STILL_DISTANCE`) is not, unless the next frame finds it still
there. A row never spans a move, a loss or a new place of the target (one more than
:data:`SAME_PLACE_OVERLAP` and :data:`SAME_PLACE_DISTANCE` away from where it settled): the
readings so far make a shorter row. Each place the target settles in is told and drawn, so the
user can confirm what is read.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .calibration import Calibration
from .conditions import Conditions, Radiometry
from .errors import InputError
from .frames import FramePair, thermal_output
from .registration import DepthOnThermal, Registration
from .sweep import COLUMNS
from .target import TargetSpec, overlap

FloatArray = NDArray[np.float64]

COLLECTED_COLUMNS = (*COLUMNS, "frame", "time_s", "target_px")
"""The columns ``collect-sweep`` writes: the sweep CSV's, then the first frame of each row,
its mean thermal time (s) and the target's size (thermal pixels)."""

STILL_OVERLAP, STILL_DISTANCE, STILL_DISTANCE_M = 0.8, 0.005, 0.002
"""The target held still since the previous frame: the two overlap by 80 % (intersection over
union) and their distances differ by 0.5 % + 2 mm or less (the depth noise of a median over
the target is far below; a plate carried at 10 cm/s moves 1 cm between frames)."""

SAME_PLACE_OVERLAP, SAME_PLACE_DISTANCE = 0.5, 0.05
"""A target that settles within these of where it settled before is in the same place."""

VOX_LIMITS_K = (200.0, 400.0)
"""FPA temperatures a working Lepton reports; outside: no telemetry (zeros or NaN)."""

MAX_OVERLAYS = 50


@dataclass(frozen=True)
class Reading:
    """One frame's reading of the target (units in the names; ``frame`` its index)."""

    frame: int
    time_s: float
    distance_m: float
    vox_temp_c: float
    measured_temp_c: float
    raw_counts: float
    target_px: int


@dataclass
class CollectStats:
    """What a collection saw: pairs, FFC pairs skipped, pairs without the target, pairs whose
    target moved (not read), places the target settled in and the overlays written."""

    pairs: int = 0
    ffc_pairs: int = 0
    missing_pairs: int = 0
    moving_pairs: int = 0
    placements: int = 0
    overlays: list[Path] = field(default_factory=list)


Overlay = Callable[[FloatArray, NDArray[np.bool_] | None, str], Path | None]
"""Draws a frame's apparent temperature (h, w, C) with the target (None: none) and a title;
returns the PNG written, or None."""


class SweepCollector:
    """Pairs -> sweep rows (module docstring).

    calibration: the rig's (registration of depth to thermal pixels); target: how the target
    is chosen; reference_temp_c: its true temperature (contact thermometer), C; conditions:
    emissivity, air temperature and humidity written with each row (the readings use the
    emissivity and the reflected temperature); average: readings per row; overlay: draws the
    target each time it is placed; say: where lines for the user go (target found, lost,
    changed); source: the name messages give.
    """

    def __init__(
        self,
        calibration: Calibration,
        target: TargetSpec,
        reference_temp_c: float,
        conditions: Conditions,
        average: int = 1,
        overlay: Overlay | None = None,
        say: Callable[[str], None] | None = None,
        source: str = "source",
    ) -> None:
        target.check_inside(calibration.thermal.shape)
        self.calibration = calibration
        self.registration = Registration(calibration)
        self.radiometry = Radiometry(conditions)
        self.target = target
        self.reference_temp_c = reference_temp_c
        self.conditions = conditions
        self.average = average
        self.overlay = overlay
        self.say = say or (lambda line: None)
        self.source = source
        self.stats = CollectStats()
        self._group: list[Reading] = []  # readings of the row in progress
        self._previous: _Seen | None = None  # the target in the previous frame
        self._pending: Reading | None = None  # a reading waiting for the next frame
        self._place: _Seen | None = None  # where the target settled
        self._lost_at: int | None = None  # the frame it was lost in, until found
        self._tells_vox: bool | None = None  # whether the camera tells its VOx temperature
        self.last_temp_c: FloatArray | None = None

    # -- per pair ---------------------------------------------------------------------------

    def add(self, pair: FramePair) -> list[dict[str, float]]:
        """The rows this pair completes (usually none or one)."""
        self.stats.pairs += 1
        if pair.telemetry.in_ffc:
            self.stats.ffc_pairs += 1
            return []
        self._check_vox(pair)
        near = self.registration.depth_to_thermal(pair.depth)
        counts = pair.thermal.astype(np.float64)
        output = thermal_output(pair.telemetry, self.calibration.thermal_output)
        # NaN where the values are invalid
        temp = self.radiometry.with_output(output).celsius(counts)
        self.last_temp_c = temp
        mask = self.target.find(near.z_m, temp, self.reference_temp_c)
        distance = np.nan if mask is None else self._distance_m(pair.depth, temp, near, mask)
        if mask is None or not np.isfinite(distance):
            return self._missed(pair)
        reading = Reading(
            pair.index,
            pair.thermal_time_s,
            distance,
            pair.telemetry.fpa_temp_c,
            float(np.mean(temp[mask])),
            float(np.mean(counts[mask])),
            int(mask.sum()),
        )
        seen = _Seen(mask, distance)
        previous, self._previous = self._previous, seen
        if previous is None or not seen.still_since(previous):
            # moving (or just found): read only if the next frame finds it still here
            self.stats.moving_pairs += self._pending is not None
            self._pending = reading
            return self.finish()
        rows = []
        if self._place is None or not seen.same_place(self._place):
            rows += self.finish()
            self._settled(pair.index, temp, seen)
        elif self._lost_at is not None:
            self.say(f"frame {pair.index}: target found again (lost at frame {self._lost_at})")
        self._lost_at = None
        for r in (self._pending, reading):
            if r is not None:
                self._group.append(r)
                if len(self._group) >= self.average:
                    rows += self.finish()
        self._pending = None
        return rows

    def _check_vox(self, pair: FramePair) -> None:
        """A camera tells its VOx (FPA) temperature in every frame, or in none (an InfiRay P2
        Pro: the rows' vox_temp_c are then empty, said once); one that stops telling it, or
        tells a value no working camera reports, stops the sweep with one line."""
        fpa_k = pair.telemetry.fpa_temp_k
        told = not np.isnan(fpa_k)
        if self._tells_vox is None:
            self._tells_vox = told
            if not told:
                self.say(
                    f"frame {pair.index}: the camera tells no sensor (VOx) temperature: the "
                    "rows' vox_temp_c are left empty (fit-compensation --method radiance fits "
                    "them without it; the paper's method needs it)"
                )
        if told != self._tells_vox or (told and not VOX_LIMITS_K[0] < fpa_k < VOX_LIMITS_K[1]):
            raise InputError(
                f"{self.source}: frame {pair.index}: no VOx (FPA) temperature in the telemetry "
                f"({fpa_k:g} K); a sweep needs the Lepton's telemetry: enable it and record again"
            )

    def finish(self) -> list[dict[str, float]]:
        """The row of the readings not yet in one (none if there are none)."""
        if not self._group:
            return []
        g, self._group = self._group, []
        mean = {
            name: float(np.mean([getattr(r, name) for r in g]))
            for name in ("distance_m", "vox_temp_c", "measured_temp_c", "raw_counts", "time_s")
        }
        c = self.conditions
        return [
            {
                **mean,
                "reference_temp_c": self.reference_temp_c,
                "ambient_temp_c": float(c.ambient_temp_c),
                "humidity_pct": float(c.humidity_pct),
                "emissivity": float(c.emissivity),
                "n": float(len(g)),
                "frame": float(g[0].frame),
                "target_px": float(np.mean([r.target_px for r in g])),
            }
        ]

    # -- steps ------------------------------------------------------------------------------

    def _distance_m(
        self,
        depth: NDArray[np.uint16],
        temp: FloatArray,
        near: DepthOnThermal,
        mask: NDArray[np.bool_],
    ) -> float:
        """Median range (m) from the thermal camera of the depth pixels whose surface the
        target's thermal pixels see (occlusion-aware registration; not the z-buffer's nearest
        sample, which lies short by about two noise SDs)."""
        cal = self.calibration
        index = np.empty(depth.shape, np.int32)
        self.registration.thermal_to_depth(depth, temp, nearest=near, thermal_index=index)
        on = np.flatnonzero(np.where(index >= 0, mask.ravel()[index], False))
        if on.size == 0:
            return np.nan
        v, u = np.divmod(on, depth.shape[1])
        z = depth.ravel()[on] * cal.depth_scale_m
        points = cal.thermal_from_depth.apply(cal.depth.deproject(np.stack([u, v], -1), z))
        return float(np.median(np.linalg.norm(points, axis=-1)))

    def _missed(self, pair: FramePair) -> list[dict[str, float]]:
        """A pair without the target: say so once, end the row in progress."""
        self.stats.missing_pairs += 1
        self.stats.moving_pairs += self._pending is not None
        self._pending = self._previous = None
        if self._place is not None and self._lost_at is None:
            self._lost_at = pair.index
            self.say(f"frame {pair.index}: target lost")
        return self.finish()

    def _settled(self, frame: int, temp: FloatArray, seen: _Seen) -> None:
        """The target settled in a new place: say where, and draw it."""
        self._place = seen
        self.stats.placements += 1
        size = (
            f"{int(seen.mask.sum())} px at {seen.distance_m:.2f} m, "
            f"reading {np.mean(temp[seen.mask]):.2f} C"
        )
        what = "target found" if self.stats.placements == 1 else "target moved"
        line = f"frame {frame}: {what}: {size}"
        if self.overlay is not None and len(self.stats.overlays) < MAX_OVERLAYS:
            path = self.overlay(temp, seen.mask, f"frame {frame}: target {self.target} ({size})")
            if path is not None:
                self.stats.overlays.append(path)
                line += f" (drawn in {path})"
        self.say(line)

    def close(self) -> list[dict[str, float]]:
        """The last row; a reading still waiting for its next frame is not read."""
        self.stats.moving_pairs += self._pending is not None
        self._pending = None
        return self.finish()


@dataclass(frozen=True, eq=False)
class _Seen:
    """Where the target is in one frame: its thermal pixels and its distance (m)."""

    mask: NDArray[np.bool_]
    distance_m: float

    def _near(self, other: _Seen, min_overlap: float, fraction: float, plus_m: float) -> bool:
        return (
            overlap(self.mask, other.mask) >= min_overlap
            and abs(self.distance_m - other.distance_m) <= fraction * other.distance_m + plus_m
        )

    def still_since(self, previous: _Seen) -> bool:
        return self._near(previous, STILL_OVERLAP, STILL_DISTANCE, STILL_DISTANCE_M)

    def same_place(self, place: _Seen) -> bool:
        return self._near(place, SAME_PLACE_OVERLAP, SAME_PLACE_DISTANCE, 0.0)
