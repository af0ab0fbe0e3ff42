"""Pairing in time: each thermal frame (~8.7 fps) with the nearest depth frame (30 fps).

A pair is kept when |depth time - thermal time| <= ``max_skew_s`` (20 ms by default: at 30 fps
depth frames are 33 ms apart, so the nearest one is at most 16.7 ms away when the depth stream
has no gaps); otherwise the thermal frame is dropped and counted. Ties go to the earlier depth
frame. A depth frame may serve more than one thermal frame (it never does at these rates).

:func:`pair_times` is the pure reference over two time arrays; :class:`StreamPairer` does the
same online, frame by frame, and gives the same pairs (tested against each other).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..frames import DepthFrame, Match, ThermalFrame, pair_of

DEFAULT_MAX_SKEW_S = 0.020


@dataclass
class PairingStats:
    """Counts and skew of a pairing: thermal frames seen, pairs made, thermal frames dropped
    (no depth frame within the threshold), depth frames seen, and the skews (depth - thermal,
    seconds) of the pairs made."""

    thermal_frames: int = 0
    depth_frames: int = 0
    pairs: int = 0
    dropped: int = 0
    skews_s: list[float] = field(default_factory=list)

    def add_pair(self, skew_s: float) -> None:
        self.pairs += 1
        self.skews_s.append(skew_s)

    @property
    def median_abs_skew_ms(self) -> float:
        return float(np.median(np.abs(self.skews_s)) * 1e3) if self.skews_s else float("nan")

    @property
    def max_abs_skew_ms(self) -> float:
        return float(np.max(np.abs(self.skews_s)) * 1e3) if self.skews_s else float("nan")

    def summary(self) -> str:
        """One line: ``pairs 87, dropped 0 of 87 thermal frames, |skew| median 8.1 ms, max
        16.4 ms``."""
        return (
            f"pairs {self.pairs}, dropped {self.dropped} of {self.thermal_frames} thermal "
            f"frames, |skew| {self._skews()}"
        )

    def skew_summary(self) -> str:
        """One line for pairs made elsewhere (nothing dropped here): ``pairs 87, |skew|
        median 8.1 ms, max 16.4 ms``."""
        return f"pairs {self.pairs}, |skew| {self._skews()}"

    def _skews(self) -> str:
        return f"median {self.median_abs_skew_ms:.1f} ms, max {self.max_abs_skew_ms:.1f} ms"


def nearest_index(depth_times_s: NDArray[np.float64], t: float) -> int:
    """Index of the time in the sorted ``depth_times_s`` nearest to ``t`` (ties: the earlier);
    -1 when there is none."""
    n = len(depth_times_s)
    if n == 0:
        return -1
    j = int(np.searchsorted(depth_times_s, t, side="left"))
    if j == 0:
        return 0
    if j == n:
        return n - 1
    before, after = depth_times_s[j - 1], depth_times_s[j]
    return j - 1 if t - before <= after - t else j


def pair_times(
    depth_times_s: ArrayLike, thermal_times_s: ArrayLike, max_skew_s: float = DEFAULT_MAX_SKEW_S
) -> tuple[list[tuple[int, int]], PairingStats]:
    """Pair two streams by time (pure reference).

    depth_times_s, thermal_times_s: capture times in seconds on one clock, each increasing.
    Returns the pairs as ``(depth_index, thermal_index)`` in thermal order and the stats.
    """
    if max_skew_s < 0:
        raise ValueError(f"max_skew_s must be >= 0, got {max_skew_s}")
    d = np.asarray(depth_times_s, dtype=np.float64)
    t = np.asarray(thermal_times_s, dtype=np.float64)
    if np.any(np.diff(d) < 0) or np.any(np.diff(t) < 0):
        raise ValueError("stream times must not decrease")
    stats = PairingStats(thermal_frames=len(t), depth_frames=len(d))
    pairs: list[tuple[int, int]] = []
    for i, ti in enumerate(t):
        j = nearest_index(d, float(ti))
        if j >= 0 and abs(d[j] - ti) <= max_skew_s:
            pairs.append((j, i))
            stats.add_pair(float(d[j] - ti))
        else:
            stats.dropped += 1
    return pairs, stats


class StreamPairer:
    """Online pairing of a depth stream and a thermal stream, frames arriving in any
    interleaving (each stream in time order).

    ``add_depth`` / ``add_thermal`` return the pairs they complete (as :class:`Match`: the
    pair and the frames it was made of), numbered from 0; ``flush()`` decides what
    is still waiting at the end. A thermal frame at time t is decided once a depth frame at
    or after t has arrived (its nearest depth frame is then known). Depth frames that can no
    longer be the nearest to any thermal frame to come (older than the last depth frame at or
    before the latest thermal time) are forgotten, so the result equals :func:`pair_times`;
    before the first thermal frame only ``history_s`` seconds of depth frames are kept.
    """

    def __init__(self, max_skew_s: float = DEFAULT_MAX_SKEW_S, history_s: float = 2.0) -> None:
        if max_skew_s < 0:
            raise ValueError(f"max_skew_s must be >= 0, got {max_skew_s}")
        self.max_skew_s = max_skew_s
        self.history_s = history_s
        self.stats = PairingStats()
        self._depth: deque[DepthFrame] = deque()
        self._waiting: deque[ThermalFrame] = deque()
        self._next_index = 0
        self._last_thermal_s = float("-inf")

    def add_depth(self, frame: DepthFrame) -> list[Match]:
        self.stats.depth_frames += 1
        self._depth.append(frame)
        return self._decide(final=False)

    def add_thermal(self, frame: ThermalFrame) -> list[Match]:
        self.stats.thermal_frames += 1
        self._last_thermal_s = frame.time_s
        self._waiting.append(frame)
        return self._decide(final=False)

    def flush(self) -> list[Match]:
        """Decide every waiting thermal frame with the depth frames seen so far."""
        return self._decide(final=True)

    def _decide(self, final: bool) -> list[Match]:
        out: list[Match] = []
        while self._waiting:
            th = self._waiting[0]
            if not final and (not self._depth or self._depth[-1].time_s < th.time_s):
                break  # a nearer depth frame may still come
            self._waiting.popleft()
            times = np.fromiter((f.time_s for f in self._depth), np.float64, len(self._depth))
            j = nearest_index(times, th.time_s)
            if j >= 0 and abs(times[j] - th.time_s) <= self.max_skew_s:
                d = self._depth[j]
                out.append(Match(d, th, pair_of(d, th, self._next_index)))
                self._next_index += 1
                self.stats.add_pair(float(times[j] - th.time_s))
            else:
                self.stats.dropped += 1
        if self._waiting:
            horizon = self._waiting[0].time_s
        elif self._last_thermal_s > float("-inf"):
            horizon = self._last_thermal_s  # thermal frames to come are no earlier
        else:
            horizon = self._latest() - self.history_s
        # keep the newest depth frame at or before the horizon: it may be the nearest
        while len(self._depth) > 1 and self._depth[1].time_s <= horizon:
            self._depth.popleft()
        return out

    def _latest(self) -> float:
        return self._depth[-1].time_s if self._depth else float("-inf")
