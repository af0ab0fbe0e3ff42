"""Recording and measuring sessions over a source: opened in order, closed in every case.

:func:`record_session` is what ``thermodepth record`` runs, :func:`run_session` what
``thermodepth run`` runs. A measuring pipeline that also records (``run --record``) iterates
``source.pairs(recorder.add)``: the source's FramePairs, while a
:class:`~thermodepth.io.recording.Recorder` stores every event. Both sessions close through
one routine: the source first (no more frames), then the recording, with the closing
attributes :func:`closing_attrs` builds (why it stopped, pairing statistics, the source's
counters).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

from .calibration import Calibration
from .errors import InputError, ThermodepthError
from .frames import DepthFrame, Match, ThermalFrame
from .io.measurements import MeasurementWriter, jsonable
from .io.recording import Recorder, RecorderStats, RecordingWriter, check_output
from .sources.base import DeviceLostError, Source, event_time_s
from .sources.pairing import PairingStats


@dataclass(kw_only=True)
class SessionResult:
    """What every session reports: why it stopped (``"frames"``, ``"duration"``, ``"end"``
    (the source ended), ``"interrupted"`` (Ctrl-C), ``"device lost"`` or ``"error"``, with
    ``error``), the recorder's stats if it recorded, the pairing statistics (sources that pair
    in time) and the source's counters (frames it skipped, by name; see
    :meth:`~thermodepth.sources.base.Source.counters`)."""

    stopped: str = "end"
    error: str | None = None
    recorder: RecorderStats | None = None
    pairing: PairingStats | None = None
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


def closing_attrs(result: SessionResult) -> dict[str, Any]:
    """The attributes a recording is closed with: ``stopped`` (and ``error``), ``pairing``
    (pairs, drops, skew in ms) where the source pairs in time, and ``source_counters``."""
    attrs: dict[str, Any] = {"stopped": result.stopped, "source_counters": dict(result.counters)}
    if result.error is not None:
        attrs["error"] = result.error
    p = result.pairing
    if p is not None:
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


def check_outputs(
    record: str | Path | None = None, out_dir: str | Path | None = None, overwrite: bool = False
) -> None:
    """Refuse outputs that cannot be created, before any camera starts: a recording path that
    exists (unless ``overwrite`` and it is a recording; see
    :func:`~thermodepth.io.recording.check_output`) and a measurements directory that is a
    file. One InputError line each."""
    if record is not None:
        check_output(record, overwrite)
    if out_dir is not None and Path(out_dir).exists() and not Path(out_dir).is_dir():
        raise InputError(f"{out_dir}: not a directory (measurements go into a directory)")


def open_recorder(
    source: Source,
    out: str | Path,
    calibration: Calibration | None = None,
    overwrite: bool = False,
    settings: dict[str, Any] | None = None,
) -> Recorder:
    """A background recorder for ``source`` at ``out``: blocking for files and the simulator
    (nothing dropped), dropping for live cameras (never stalls them). The recording stores
    the source's calibration (else ``calibration``), its settings updated with ``settings``,
    and the depth camera's own intrinsics and depth unit where the source has them. Refuses
    (InputError) to write over a path the source reads."""
    writer = RecordingWriter(
        out,
        source.calibration or calibration,
        {**source.settings(), **(settings or {})},
        source=source.name,
        overwrite=overwrite,
        inputs=source.files,
        device_depth=source.device_depth,
    )
    return Recorder(writer, block=not source.live)


R = TypeVar("R", bound=Recorder | None)


@contextmanager
def _session(source: Source, result: SessionResult, open_outputs: Callable[[], R]) -> Iterator[R]:
    """The frame of every session: ``open_outputs()`` (the recorder, if any), then the body
    under :func:`stopping`; in every case (an output that cannot be created included) the
    source is closed, its counters noted, and the recording closed with
    :func:`closing_attrs`."""
    recorder = None
    try:
        recorder = open_outputs()
        if recorder is not None:
            result.recorder = recorder.stats
        with stopping(result):
            yield recorder
    finally:
        try:
            source.close()
            result.counters = source.counters()
        finally:  # a source that fails to close (a second Ctrl-C) still leaves a closed recording
            if recorder is not None:
                recorder.close(closing_attrs(result))


def record_session(
    source: Source,
    out: str | Path,
    *,
    duration_s: float | None = None,
    frames: int | None = None,
    calibration: Calibration | None = None,
    overwrite: bool = False,
    progress: Callable[[int], None] | None = None,
) -> RecordResult:
    """Record ``source`` into a new recording at ``out`` until ``frames`` units (pairs; for a
    single-camera source, its frames) are recorded, ``duration_s`` of source time has passed,
    the source ends, Ctrl-C, or a device is lost. The source and the recording are closed in
    every case (the recording keeps every frame written). ``progress(n)`` is called per
    unit."""
    unit: type = Match
    if source.streams == {"depth"}:
        unit = DepthFrame
    elif source.streams == {"thermal"}:
        unit = ThermalFrame
    result = RecordResult(path=Path(out), pairing=source.pairing)
    t0: float | None = None
    opened = functools.partial(open_recorder, source, out, calibration, overwrite)
    with _session(source, result, opened) as recorder:
        if frames is not None and frames <= 0:
            result.stopped = "frames"
            return result
        for event in source.events():
            t = event_time_s(event)
            t0 = t if t0 is None else t0
            if duration_s is not None and t - t0 >= duration_s:
                result.stopped = "duration"
                break
            recorder.add(event)
            if isinstance(event, unit):
                result.counted += 1
                if progress:
                    progress(1)
                if frames is not None and result.counted >= frames:
                    result.stopped = "frames"
                    break
    return result


def run_session(
    source: Source,
    pipeline: Any,
    *,
    frames: int | None = None,
    record: str | Path | None = None,
    out_dir: str | Path | None = None,
    on_frame: Callable[[Any], None] | None = None,
    record_settings: dict[str, Any] | None = None,
) -> RunResult:
    """Fuse every pair of ``source`` through ``pipeline`` (a
    :class:`~thermodepth.pipeline.Pipeline`) until ``frames`` pairs, the end, Ctrl-C or a lost
    device; optionally record everything the source emits at ``record`` (with
    ``record_settings`` added to the recording's settings; closed cleanly in every case) and
    write the measurements into ``out_dir``
    (:class:`~thermodepth.io.measurements.MeasurementWriter`). ``on_frame(fused)`` per frame.
    A source without pairs is refused before anything is created; the source is closed in
    every case."""
    result = RunResult(pairing=source.pairing)
    sink: MeasurementWriter | None = None

    def open_outputs() -> Recorder | None:
        nonlocal sink
        source.require_pairs()
        if out_dir is not None:
            try:
                sink = MeasurementWriter(out_dir)
            except OSError as exc:
                raise InputError(
                    f"{out_dir}: cannot write measurements ({exc.strerror or exc})"
                ) from None
        if record is None:
            return None
        return open_recorder(source, record, pipeline.calibration, settings=record_settings)

    try:
        with _session(source, result, open_outputs) as recorder:
            pairs = source.pairs(recorder.add if recorder else None)
            for pair in pairs:
                try:
                    fused = pipeline.process(pair)
                except InputError as exc:  # a frame that does not fit: say whose
                    raise InputError(f"{source.name}: {exc}") from None
                result.frames += 1
                result.shutter_frames += fused.in_ffc
                result.events.extend(fused.events)
                if sink:
                    sink.write(fused)
                if on_frame:
                    on_frame(fused)
                if frames is not None and result.frames >= frames:
                    result.stopped = "frames"
                    break
    finally:
        if sink is not None:
            sink.close()
    return result
