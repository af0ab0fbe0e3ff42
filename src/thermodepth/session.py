"""Sessions over a source: the loops that ``record`` and ``run`` turn.

A session opens its sinks (:class:`~thermodepth.sinks.base.Sink`: the recorder, the
measurements files, and next the viewer, MQTT and batch outputs) before any frame flows,
feeds them every event the source emits and every fused frame, and closes everything in every
case: the source first (no more frames), then the sinks, each told how the session ended.

:func:`record_session` records a source (the recorder is its one sink); :func:`run_session`
fuses every pair through a :class:`~thermodepth.pipeline.Pipeline` and hands each fused
frame to the sinks.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .calibration import Calibration
from .errors import InputError, ThermodepthError, check_count
from .frames import DepthFrame, Match, StreamEvent, ThermalFrame
from .io.recording import DEFAULT_CODEC, RecorderStats
from .pipeline import Pipeline
from .progress import SILENT, Reporter
from .sinks.base import RunContext, SessionResult, Sink
from .sinks.recorder import RecorderSink
from .sources.base import DeviceLostError, Source, event_time_s
from .sources.pairing import PairingStats


@dataclass(kw_only=True)
class StreamResult(SessionResult):
    """How a session over a source's events went (:class:`SessionResult`) and how many units
    (pairs; a single camera's frames) were counted."""

    counted: int = 0


@dataclass(kw_only=True)
class RecordResult(StreamResult):
    """How a recording went (:class:`StreamResult`) and where it is."""

    path: Path
    recorder: RecorderStats = field(default_factory=RecorderStats)


@dataclass(kw_only=True)
class RunResult(SessionResult):
    """How a measuring run went (:class:`SessionResult`): frames fused, frames skipped (shutter
    closed) and alarm events."""

    frames: int = 0
    shutter_frames: int = 0
    events: list[dict[str, Any]] = field(default_factory=list)


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


def stream_session(
    source: Source,
    sinks: Sequence[Sink],
    result: StreamResult,
    *,
    duration_s: float | None = None,
    frames: int | None = None,
    calibration: Calibration | None = None,
    reporter: Reporter = SILENT,
    description: str = "",
) -> None:
    """Hand every event of ``source`` to ``sinks`` until ``frames`` units (pairs; for a
    single-camera source, its frames) are counted, ``duration_s`` of source time has passed,
    the source ends, Ctrl-C, or a device is lost; ``result`` says how it went. The source and
    the sinks (opened first with a :class:`RunContext` of ``calibration``) are closed in every
    case. ``reporter`` is told of each unit under ``description``."""
    check_count("frames", frames)
    unit = _unit_of(source)
    context = RunContext(source, calibration)
    skews: list[float] = []
    t0: float | None = None
    with (
        reporter.task(description or source.name, frames) as advance,
        _session(source, result, sinks, context),
    ):
        for event in source.events():
            t = event_time_s(event)
            t0 = t if t0 is None else t0
            if duration_s is not None and t - t0 >= duration_s:
                result.stopped = "duration"
                break
            for sink in sinks:
                sink.event(event)
            if isinstance(event, Match):
                skews.append(event.pair.skew_s)
            if isinstance(event, unit):
                result.counted += 1
                advance(1)
                if frames is not None and result.counted >= frames:
                    result.stopped = "frames"
                    break
    _ended(result, source, sinks, skews)


def record_session(
    source: Source,
    out: str | Path,
    *,
    duration_s: float | None = None,
    frames: int | None = None,
    calibration: Calibration | None = None,
    overwrite: bool = False,
    reporter: Reporter = SILENT,
    depth_frames: str = "all",
    codec: str = DEFAULT_CODEC,
) -> RecordResult:
    """Record ``source`` into a new recording at ``out`` (:func:`stream_session` with the
    recorder as its one sink: the recording keeps every frame written, whatever ends it);
    ``depth_frames``: all of them, or only the ``"paired"`` ones; ``codec``: the images'
    (:data:`~thermodepth.io.recording.format.CODECS`)."""
    result = RecordResult(path=Path(out), pairing=source.pairing)
    recorder = RecorderSink(out, overwrite=overwrite, depth_frames=depth_frames, codec=codec)
    try:
        stream_session(
            source,
            [recorder],
            result,
            duration_s=duration_s,
            frames=frames,
            calibration=calibration,
            reporter=reporter,
            description=f"recording {source.name}",
        )
    finally:
        result.recorder = recorder.stats
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
    _ended(result, source, sinks, skews)
    return result


def _ended(
    result: SessionResult, source: Source, sinks: Sequence[Sink], skews: list[float]
) -> None:
    """What a session that ended (not by an error) tells: each sink's summary line and, for
    a source that does not pair in time (the simulator pairs its own frames; a recording's
    pairs were made live), the pairing statistics of the pairs the session saw, with who
    paired them."""
    result.outputs = [line for sink in sinks if (line := sink.summary()) is not None]
    if result.pairing is not None or not skews:
        return
    result.pairing = PairingStats(
        thermal_frames=len(skews), pairs=len(skews), skews_s=[float(s) for s in skews]
    )
    result.pairing_by = source.paired_by or source.name
