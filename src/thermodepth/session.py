"""Recording a source: every event it emits into a crash-safe Zarr recording.

:func:`record_session` is what ``thermodepth record`` runs. :func:`tee` is the seam for a
measuring pipeline that also records (``thermodepth run --record``): it yields the source's
FramePairs while a :class:`~thermodepth.io.recording.Recorder` stores every event.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .calibration import Calibration
from .frames import DepthFrame, FramePair, Match, ThermalFrame
from .io.measurements import MeasurementWriter
from .io.recording import Recorder, RecorderStats, RecordingWriter
from .sources.base import DeviceLostError, Source, event_time_s
from .sources.pairing import PairingStats


@contextmanager
def stopping(result: RecordResult | RunResult) -> Iterator[None]:
    """Ctrl-C and a lost device end a session cleanly: they set ``result.stopped`` (and
    ``result.error``) instead of propagating, so the caller's ``finally`` closes what it
    opened and every frame up to then is kept."""
    try:
        yield
    except KeyboardInterrupt:
        result.stopped = "interrupted"
    except DeviceLostError as exc:
        result.stopped = "device lost"
        result.error = str(exc)


@dataclass
class RecordResult:
    """How a recording went: what was written and dropped, pairing statistics (for sources
    that pair in time), and why it stopped: ``"frames"``, ``"duration"``, ``"end"`` (the
    source ended), ``"interrupted"`` (Ctrl-C) or ``"device lost"`` (with ``error``)."""

    path: Path
    recorder: RecorderStats
    pairing: PairingStats | None = None
    stopped: str = "end"
    error: str | None = None
    counted: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


def open_recorder(
    source: Source,
    out: str | Path,
    calibration: Calibration | None = None,
    overwrite: bool = False,
    settings: dict[str, Any] | None = None,
) -> Recorder:
    """A background recorder for ``source`` at ``out``: blocking for files and the simulator
    (nothing dropped), dropping for live cameras (never stalls them)."""
    writer = RecordingWriter(
        out,
        source.calibration or calibration,
        {**source.settings(), **(settings or {})},
        source=source.name,
        overwrite=overwrite,
    )
    return Recorder(writer, block=not source.live)


def tee(source: Source, recorder: Recorder) -> Iterator[FramePair]:
    """Yield the source's FramePairs while the recorder stores every event (raw stream frames
    included). The pipeline's ``run --record`` seam."""
    for event in source.events():
        recorder.add(event)
        if isinstance(event, Match):
            yield event.pair


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
    the source ends, Ctrl-C, or a device is lost. The recording is closed in every case
    (and keeps every frame written). ``progress(n)`` is called per unit."""
    unit: type = Match
    if source.streams == {"depth"}:
        unit = DepthFrame
    elif source.streams == {"thermal"}:
        unit = ThermalFrame
    recorder = open_recorder(source, out, calibration, overwrite)
    result = RecordResult(Path(out), recorder.stats, source.pairing)
    t0: float | None = None
    try:
        with stopping(result):
            if frames is not None and frames <= 0:
                result.stopped = "frames"
            else:
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
    finally:
        source.close()
        extra: dict[str, Any] = {"stopped": result.stopped}
        if source.pairing is not None:
            p = source.pairing
            extra["pairing"] = {
                "pairs": p.pairs,
                "dropped": p.dropped,
                "thermal_frames": p.thermal_frames,
                "depth_frames": p.depth_frames,
                "median_abs_skew_ms": _finite(p.median_abs_skew_ms),
                "max_abs_skew_ms": _finite(p.max_abs_skew_ms),
            }
        recorder.close(extra)
    return result


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


@dataclass
class RunResult:
    """How a measuring run went: frames fused, frames skipped (shutter closed), alarm events,
    why it stopped (as :class:`RecordResult`), and the recording's stats if one was made."""

    frames: int = 0
    shutter_frames: int = 0
    events: list[dict[str, Any]] = field(default_factory=list)
    stopped: str = "end"
    error: str | None = None
    recorder: RecorderStats | None = None
    pairing: PairingStats | None = None


def run_session(
    source: Source,
    pipeline: Any,
    *,
    frames: int | None = None,
    record: str | Path | None = None,
    out_dir: str | Path | None = None,
    on_frame: Callable[[Any], None] | None = None,
) -> RunResult:
    """Fuse every pair of ``source`` through ``pipeline`` (a
    :class:`~thermodepth.pipeline.Pipeline`) until ``frames`` pairs, the end, Ctrl-C or a lost
    device; optionally record everything the source emits at ``record`` (closed cleanly in
    every case) and write the measurements into ``out_dir``
    (:class:`~thermodepth.io.measurements.MeasurementWriter`). ``on_frame(fused)`` per frame."""
    recorder = open_recorder(source, record, pipeline.calibration) if record else None
    result = RunResult(recorder=recorder.stats if recorder else None, pairing=source.pairing)
    sink = MeasurementWriter(out_dir) if out_dir is not None else None
    pairs = tee(source, recorder) if recorder else iter(source)
    try:
        with stopping(result):
            for pair in pairs:
                fused = pipeline.process(pair)
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
        source.close()
        if sink:
            sink.close()
        if recorder is not None:
            recorder.close({"stopped": result.stopped})
    return result
