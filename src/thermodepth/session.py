"""Sessions over a source: the loops that ``record`` and ``run`` turn, and the sinks they feed.

A session opens its sinks before any frame flows, feeds them, and closes everything in every
case: the source first (no more frames), then the sinks, each told how the session ended.

A **sink** (:class:`Sink`) is whatever consumes a session: the recorder (every raw event the
source emits), the measurements files, and next the live viewer, MQTT and batch outputs. Each
is one small object with ``open``, ``event``, ``frame`` and ``close``; a session calls them
and knows nothing else of them, so a new sink touches neither the pipeline nor this loop.

:func:`record_session` records a source (the recorder is its one sink); :func:`run_session`
fuses every pair through a :class:`~thermodepth.pipeline.Pipeline` and hands each fused
frame to the sinks.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from .calibration import Calibration
from .errors import InputError, ThermodepthError, check_count
from .frames import DepthFrame, Match, StreamEvent, ThermalFrame
from .io.measurements import jsonable
from .io.recording import RecorderStats
from .pipeline import FusedFrame, Pipeline
from .progress import SILENT, Reporter
from .sources.base import DeviceLostError, Source, event_time_s
from .sources.pairing import PairingStats


@dataclass(kw_only=True)
class SessionResult:
    """What every session reports: why it stopped (``"frames"``, ``"duration"``, ``"end"``
    (the source ended), ``"interrupted"`` (Ctrl-C), ``"device lost"`` or ``"error"``, with
    ``error``), the recorder's stats if it recorded, the pairing statistics (of the source's
    pairing in time; for sources that do not pair, of the pairs the session saw, with
    ``pairing_by`` saying who paired them) and the source's counters (frames it skipped, by
    name; see :meth:`~thermodepth.sources.base.Source.counters`)."""

    stopped: str = "end"
    error: str | None = None
    recorder: RecorderStats | None = None
    pairing: PairingStats | None = None
    pairing_by: str | None = None
    counters: dict[str, int] = field(default_factory=dict)


@dataclass(kw_only=True)
class RecordResult(SessionResult):
    """How a recording went (:class:`SessionResult`), where it is, and how many units
    (pairs; a single camera's frames) were counted."""

    path: Path
    recorder: RecorderStats = field(default_factory=RecorderStats)
    counted: int = 0


@dataclass(kw_only=True)
class RunResult(SessionResult):
    """How a measuring run went (:class:`SessionResult`): frames fused, frames skipped (shutter
    closed), alarm events, and each sink's closing line for the user."""

    frames: int = 0
    shutter_frames: int = 0
    events: list[dict[str, Any]] = field(default_factory=list)
    outputs: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class RunContext:
    """What a sink may need to open: the source (its name, calibration, settings, files,
    whether it is live), the calibration frames are fused with (None when only recording),
    the pipeline's settings, and ``provenance``: what a recording stores of the run's
    settings (the settings file's text, the compensation model's hash)."""

    source: Source
    calibration: Calibration | None = None
    pipeline: Pipeline | None = None
    provenance: dict[str, Any] = field(default_factory=dict)


class Sink(Protocol):
    """A consumer of a session (see the module docstring). ``check`` refuses, before any
    camera starts, what ``open`` would refuse (an output that exists); ``open`` before any
    frame (it may still refuse with an InputError: nothing has flowed); ``event`` for every
    event the source emits (raw frames and pairs, in order); ``frame`` for every fused frame
    (runs only); ``close`` once, in every case, with how the session ended; ``summary`` a
    line for the user at the end (None: nothing to say)."""

    def check(self) -> None: ...

    def open(self, context: RunContext) -> None: ...

    def event(self, event: StreamEvent) -> None: ...

    def frame(self, fused: FusedFrame) -> None: ...

    def close(self, result: SessionResult) -> None: ...

    def summary(self) -> str | None: ...


class BaseSink:
    """A sink that does nothing: subclasses override what they consume."""

    def check(self) -> None:
        """Nothing to refuse."""

    def open(self, context: RunContext) -> None:
        """Nothing to open."""

    def event(self, event: StreamEvent) -> None:
        """Raw events are not wanted."""

    def frame(self, fused: FusedFrame) -> None:
        """Fused frames are not wanted."""

    def close(self, result: SessionResult) -> None:
        """Nothing to close."""

    def summary(self) -> str | None:
        return None


@contextmanager
def stopping(result: SessionResult) -> Iterator[None]:
    """Ctrl-C and a lost device end a session cleanly: they set ``result.stopped`` (and
    ``result.error``) instead of propagating, so the caller's ``finally`` closes what it
    opened and every frame up to then is kept. Other errors of the project are noted in
    ``result`` (stopped ``"error"``, so the recording says so) and propagate."""
    try:
        yield
    except KeyboardInterrupt:
        result.stopped = "interrupted"
    except DeviceLostError as exc:
        result.stopped = "device lost"
        result.error = str(exc)
    except ThermodepthError as exc:
        result.stopped = "error"
        result.error = str(exc)
        raise


def closing_attrs(result: SessionResult) -> dict[str, Any]:
    """The attributes a recording is closed with: ``stopped`` (and ``error``), ``pairing``
    (pairs, drops, skew in ms) where the source pairs in time, and ``source_counters``."""
    attrs: dict[str, Any] = {"stopped": result.stopped, "source_counters": dict(result.counters)}
    if result.error is not None:
        attrs["error"] = result.error
    p = result.pairing
    if p is not None and result.pairing_by is None:
        attrs["pairing"] = jsonable(
            {
                "pairs": p.pairs,
                "dropped": p.dropped,
                "thermal_frames": p.thermal_frames,
                "depth_frames": p.depth_frames,
                "median_abs_skew_ms": p.median_abs_skew_ms,
                "max_abs_skew_ms": p.max_abs_skew_ms,
            }
        )
    return attrs


@contextmanager
def _session(
    source: Source, result: SessionResult, sinks: Sequence[Sink], context: RunContext
) -> Iterator[None]:
    """The frame of every session: each sink opened in turn, then the body under
    :func:`stopping`; in every case (a sink that cannot open included) the source is closed,
    its counters noted, and every sink that opened closed with the result."""
    with ExitStack() as opened:
        try:
            for sink in sinks:
                sink.open(context)
                opened.callback(sink.close, result)
            with stopping(result):
                yield
        finally:
            # a source that fails to close (a second Ctrl-C) still leaves closed sinks
            source.close()
            result.counters = source.counters()


def _unit_of(source: Source) -> type:
    """What a recording of ``source`` counts: pairs, or a single camera's frames."""
    if source.streams == {"depth"}:
        return DepthFrame
    if source.streams == {"thermal"}:
        return ThermalFrame
    return Match


def record_session(
    source: Source,
    out: str | Path,
    *,
    duration_s: float | None = None,
    frames: int | None = None,
    calibration: Calibration | None = None,
    overwrite: bool = False,
    reporter: Reporter = SILENT,
) -> RecordResult:
    """Record ``source`` into a new recording at ``out`` until ``frames`` units (pairs; for a
    single-camera source, its frames) are recorded, ``duration_s`` of source time has passed,
    the source ends, Ctrl-C, or a device is lost. The source and the recording are closed in
    every case (the recording keeps every frame written). ``reporter`` is told of each unit.
    """
    from .sinks.recorder import RecorderSink  # the one sink of a recording

    check_count("frames", frames)
    unit = _unit_of(source)
    result = RecordResult(path=Path(out), pairing=source.pairing)
    recorder = RecorderSink(out, overwrite=overwrite)
    context = RunContext(source, calibration)
    skews: list[float] = []
    t0: float | None = None
    with (
        reporter.task(f"recording {source.name}", frames) as advance,
        _session(source, result, [recorder], context),
    ):
        result.recorder = recorder.stats
        for event in source.events():
            t = event_time_s(event)
            t0 = t if t0 is None else t0
            if duration_s is not None and t - t0 >= duration_s:
                result.stopped = "duration"
                break
            recorder.event(event)
            if isinstance(event, Match):
                skews.append(event.pair.skew_s)
            if isinstance(event, unit):
                result.counted += 1
                advance(1)
                if frames is not None and result.counted >= frames:
                    result.stopped = "frames"
                    break
    _pairs_seen(result, source, skews)
    return result


def run_session(
    source: Source,
    pipeline: Pipeline,
    *,
    frames: int | None = None,
    sinks: Sequence[Sink] = (),
    provenance: dict[str, Any] | None = None,
) -> RunResult:
    """Fuse every pair of ``source`` through ``pipeline`` until ``frames`` pairs, the end,
    Ctrl-C or a lost device, handing every event and every fused frame to ``sinks`` (opened
    first with a :class:`RunContext` holding ``provenance``, closed in every case). A source
    without pairs is refused before anything is opened; the source is closed in every case.
    """
    check_count("frames", frames)
    result = RunResult(pairing=source.pairing)
    context = RunContext(source, pipeline.calibration, pipeline, provenance or {})
    skews: list[float] = []
    try:
        source.require_pairs()
    except BaseException:
        source.close()
        raise

    def on_event(event: StreamEvent) -> None:
        for sink in sinks:
            sink.event(event)

    with _session(source, result, sinks, context):
        for pair in source.pairs(on_event):
            try:
                fused = pipeline.process(pair)
            except InputError as exc:  # a frame that does not fit: say whose
                raise InputError(f"{source.name}: {exc}") from None
            skews.append(pair.skew_s)
            result.frames += 1
            result.shutter_frames += fused.in_ffc
            result.events.extend(fused.events)
            for sink in sinks:
                sink.frame(fused)
            if frames is not None and result.frames >= frames:
                result.stopped = "frames"
                break
    result.outputs = [line for sink in sinks if (line := sink.summary()) is not None]
    _pairs_seen(result, source, skews)
    return result


def _pairs_seen(result: SessionResult, source: Source, skews: list[float]) -> None:
    """Pairing statistics for a source that does not pair in time (the simulator pairs its
    own frames; a recording's pairs were made live): those of the pairs the session saw,
    with who paired them."""
    if result.pairing is not None or not skews:
        return
    result.pairing = PairingStats(
        thermal_frames=len(skews), pairs=len(skews), skews_s=[float(s) for s in skews]
    )
    result.pairing_by = source.paired_by or source.name
