"""One rig of the monitor as a session: its source kept on the clock of a live camera
(:class:`PacedSource`), its figures (:class:`RigStatus`) and the sink that hands its frames to
the monitor's outputs (:class:`RigSink`: pre-trigger buffer, clips, continuous recording,
fail-safe, events).

Every rig's frames are stamped in Unix time, as a live camera's are (the simulator in real
time is too): a recording replayed at its recorded pace is moved onto it (its pairs released
when a camera would have sent them), so that an event's time is when it was seen and the
latency from a frame's capture to its alarm can be measured the same way for every rig. A
paced pair reached more than :data:`LATE_S` after its time is dropped and counted, as a live
camera's driver drops a frame nobody read.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..frames import DepthFrame, Match, StreamEvent, ThermalFrame
from ..pipeline import FusedFrame
from ..sinks.base import BaseSink, RunContext, SessionResult
from ..sources.base import Source
from .evidence import Evidence, PreTrigger
from .failsafe import SensorWatch
from .live import LiveView
from .storage import ContinuousRecorder

LATE_S = 1.0
"""A paced pair reached later than this after its time is dropped (a live camera's queue
would have overflowed)."""
FPS_WINDOW_S = 5.0


@dataclass
class RigStatus:
    """A rig's figures, as ``/api/status`` and ``/metrics`` show them: ``state``
    (``starting``, ``running``, ``reopening``, ``ended``, ``stopped``), frames fused, when the
    last one arrived (monotonic s), reconnects, stalls, seconds without data, pairs dropped,
    the shutter (FFC) and VOx of the last frame, the pipeline's recent times (s), how late a
    paced source's recent pairs were reached (s), the last error and what the last recovery
    did."""

    name: str
    location: str | None
    source: str
    state: str = "starting"
    frames: int = 0
    started_mono: float = field(default_factory=time.monotonic)
    opened_mono: float = field(default_factory=time.monotonic)
    last_frame_mono: float | None = None
    last_frame_time_s: float | None = None
    reconnects: int = 0
    stalls: int = 0
    seconds_without_data: float = 0.0
    dropped: int = 0
    in_ffc: bool = False
    vox_temp_c: float = float("nan")
    frozen_since_mono: float | None = None
    pipeline_s: deque[float] = field(default_factory=lambda: deque(maxlen=200))
    lag_s: deque[float] = field(default_factory=lambda: deque(maxlen=200))
    arrivals: deque[float] = field(default_factory=lambda: deque(maxlen=600))
    hottest: dict[str, Any] | None = None
    rois: dict[str, dict[str, Any]] = field(default_factory=dict)
    last_error: str | None = None
    last_recovery: str | None = None
    counters: dict[str, int] = field(default_factory=dict)

    def count_drop(self) -> None:
        self.dropped += 1

    def age_s(self, now_mono: float) -> float:
        """Seconds since the last frame (since the rig started, before its first)."""
        return now_mono - (self.last_frame_mono or self.started_mono)

    def quiet_s(self, now_mono: float) -> float:
        """Seconds this session has gone without a frame (since it opened, before its
        first): what a stall is measured by."""
        return now_mono - max(self.last_frame_mono or 0.0, self.opened_mono)

    def fps(self, now_mono: float) -> float:
        recent = [t for t in self.arrivals if t > now_mono - FPS_WINDOW_S]
        if len(recent) < 2:
            return 0.0
        return (len(recent) - 1) / max(recent[-1] - recent[0], 1e-6)

    def as_dict(self, now_mono: float) -> dict[str, Any]:
        return {
            "name": self.name,
            "location": self.location,
            "source": self.source,
            "state": self.state,
            "frames": self.frames,
            "fps": round(self.fps(now_mono), 2),
            "last_frame_age_s": round(self.age_s(now_mono), 3),
            "last_frame_time_s": self.last_frame_time_s,
            "reconnects": self.reconnects,
            "stalls": self.stalls,
            "seconds_without_data": round(self.seconds_without_data, 1),
            "dropped": self.dropped,
            "ffc": self.in_ffc,
            "vox_temp_c": None if np.isnan(self.vox_temp_c) else round(self.vox_temp_c, 3),
            "hottest": self.hottest,
            "rois": self.rois,
            "pipeline_ms": quantiles(self.pipeline_s, 1e3),
            "pace_lag_ms": quantiles(self.lag_s, 1e3),
            "last_error": self.last_error,
            "last_recovery": self.last_recovery,
            "source_counters": dict(self.counters),
        }


def quantiles(values: Iterable[float], scale: float = 1.0) -> dict[str, float | int | None]:
    """Median and 99th percentile of recent values times ``scale`` (None: none yet), and
    how many."""
    v = sorted(values)
    if not v:
        return {"median": None, "p99": None, "n": 0}
    return {
        "median": round(scale * v[len(v) // 2], 4),
        "p99": round(scale * v[min(len(v) - 1, int(0.99 * len(v)))], 4),
        "n": len(v),
    }


def _shifted(event: StreamEvent, offset_s: float, index_offset: int) -> StreamEvent:
    """An event moved ``offset_s`` later and numbered ``index_offset`` on."""
    if isinstance(event, Match):
        p = event.pair
        return Match(
            _shifted(event.depth, offset_s, index_offset),  # type: ignore[arg-type]
            _shifted(event.thermal, offset_s, index_offset),  # type: ignore[arg-type]
            replace(
                p,
                depth_time_s=p.depth_time_s + offset_s,
                thermal_time_s=p.thermal_time_s + offset_s,
                index=p.index + index_offset,
            ),
        )
    assert isinstance(event, DepthFrame | ThermalFrame)
    return replace(event, time_s=event.time_s + offset_s, index=event.index + index_offset)


class PacedSource(Source):
    """A source as a rig of the monitor sees it (module docstring): ``replay``: a recording
    replayed at its recorded pace, moved onto Unix time, again from its start each time it
    ends; ``paced``: a source that keeps its own pace on Unix time (the simulator in real
    time), whose late pairs are dropped; else (a live camera, a recording replayed fast) as
    it is. Its frames are numbered on from
    ``index_from`` (a rig's numbers go on across reopenings; ``last_index`` is the last
    pair's); how late each paced pair was reached (s) goes into ``lags_s``, and each pair
    dropped is told to ``on_drop``. ``close()`` may come from any thread (a stall) and ends
    the events at once."""

    def __init__(
        self,
        inner: Source,
        replay: bool = False,
        paced: bool = False,
        index_from: int = 0,
        lags_s: deque[float] | None = None,
        on_drop: Callable[[], None] | None = None,
    ) -> None:
        self.inner, self.replay, self.paced = inner, replay, paced or replay
        for name in ("name", "paired_by", "streams", "calibration", "pairing", "files"):
            setattr(self, name, getattr(inner, name))
        self.device_depth = inner.device_depth
        self.live = inner.live or self.paced
        self.dropped = 0
        self.lags_s = deque(maxlen=200) if lags_s is None else lags_s
        self.on_drop = on_drop or (lambda: None)
        self.last_index = index_from - 1
        self._closed = threading.Event()

    def events(self) -> Iterator[StreamEvent]:
        offset_s = 0.0
        index_offset: int | None = None
        last_due: float | None = None
        step_s = 0.1  # a replay's next pass starts one frame after its last pair
        while True:
            first: StreamEvent | None = None
            for event in self.inner.events():
                t = _time_of(event)
                if first is None:
                    first = event
                    if self.replay:
                        start = time.time() if last_due is None else last_due + step_s
                        offset_s = start - t
                    index_offset = self.last_index + 1 - _index_of(event)
                assert index_offset is not None
                due = t + offset_s
                if self.replay and self._closed.wait(max(0.0, due - time.time())):
                    return
                if self._closed.is_set():
                    return
                event = _shifted(event, offset_s, index_offset)
                if isinstance(event, Match) and self.paced:
                    lag = time.time() - due
                    if lag > LATE_S:
                        self.dropped += 1
                        self.on_drop()
                        continue
                    self.lags_s.append(lag)
                if isinstance(event, Match):
                    if last_due is not None and due > last_due:
                        step_s = due - last_due
                    last_due, self.last_index = due, event.pair.index
                yield event
            if not self.replay or first is None or self._closed.is_set():
                return

    def close(self) -> None:
        self._closed.set()
        self.inner.close()

    def settings(self) -> dict[str, Any]:
        return self.inner.settings()

    def counters(self) -> dict[str, int]:
        return {**self.inner.counters(), **({"dropped": self.dropped} if self.dropped else {})}

    def recover(self) -> str | None:
        return self.inner.recover()


def _index_of(event: StreamEvent) -> int:
    return event.pair.index if isinstance(event, Match) else event.index


def _time_of(event: StreamEvent) -> float:
    return event.pair.thermal_time_s if isinstance(event, Match) else event.time_s


class RigSink(BaseSink):
    """The monitor's sink of one rig's sessions (every reopening a session of its own):
    every event to the pre-trigger buffer (``pre``), the open clip (``evidence``) and the
    continuous recording; every fused frame's figures to ``status``, the frame to
    ``measured(sink, fused)`` and to the screens (``live``), its alarm events and sensor
    faults (``watch``) to ``emit(sink, events, fused)``."""

    def __init__(
        self,
        name: str,
        status: RigStatus,
        pre: PreTrigger,
        evidence: Evidence,
        continuous: ContinuousRecorder | None,
        watch: SensorWatch,
        emit: Callable[[RigSink, list[dict[str, Any]], FusedFrame | None], None],
        measured: Callable[[RigSink, FusedFrame], None],
        live: LiveView,
    ) -> None:
        self.name, self.status, self.pre, self.evidence = name, status, pre, evidence
        self.continuous, self.watch, self.emit, self.measured = continuous, watch, emit, measured
        self.live = live
        self.context: RunContext | None = None
        self._match_at: float | None = None
        self._previous: np.ndarray | None = None

    def open(self, context: RunContext) -> None:
        self.context = context
        self.status.state = "running"
        self.status.opened_mono = time.monotonic()
        if self.continuous is not None:
            self.continuous.open(context)

    def event(self, event: StreamEvent) -> None:
        if self.continuous is not None:
            self.continuous.add(event)
        if not isinstance(event, Match):
            return
        now = time.monotonic()
        self._match_at = time.perf_counter()
        self.pre.add(event)
        self.evidence.feed(self.name, event)
        s = self.status
        s.last_frame_mono, s.last_frame_time_s = now, event.pair.thermal_time_s
        s.arrivals.append(now)
        thermal = event.pair.thermal
        # a live sensor's noise makes two frames never equal: a repeat outside the shutter's
        # closing is a frozen stream (a stall that still sends)
        repeat = self._previous is not None and np.array_equal(thermal, self._previous)
        if repeat and not event.pair.telemetry.in_ffc:
            s.frozen_since_mono = s.frozen_since_mono or now
        else:
            s.frozen_since_mono = None
        self._previous = thermal

    def frame(self, fused: FusedFrame) -> None:
        s = self.status
        if self._match_at is not None:
            s.pipeline_s.append(time.perf_counter() - self._match_at)
        s.frames += 1
        s.in_ffc, s.vox_temp_c = fused.in_ffc, fused.vox_temp_c
        if not fused.in_ffc:
            hot = fused.hotspots[0] if fused.hotspots else None
            s.hottest = (
                None
                if hot is None
                else {
                    "max_c": hot.max_c,
                    "position_m": list(hot.centroid_m),
                    "distance_m": hot.distance_m,
                    "resolvable": hot.resolvable,
                }
            )
            s.rois = {r.name: {"max_c": r.max_c, "mean_c": r.mean_c, "min_c": r.min_c, "n": r.n,
                               "severity": r.severity}  # its class (thermodepth.severity)
                      for r in fused.rois}  # fmt: skip
        pipeline = self.context.pipeline if self.context is not None else None
        self.live.fused(fused, pipeline.alarms if pipeline is not None else None)
        events = fused.events + self.watch.frame(fused, fused.thermal_time_s)
        if events:
            self.emit(self, events, fused)
        self.measured(self, fused)

    def close(self, result: SessionResult) -> None:
        self.status.counters = dict(result.counters)
        self.status.last_error = result.error or self.status.last_error
        self._previous = None
        if self.continuous is not None:
            self.continuous.close(result)


__all__ = ["LATE_S", "PacedSource", "RigSink", "RigStatus"]
